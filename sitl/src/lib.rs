//! The car's own firmware, built for the host and driven in virtual time (software in the loop).
//!
//! drivecheck does not ship the firmware: [`build`] compiles the portable C modules of a firmware
//! tree the user points it at (`Embedded/RC_Controller` of the car's firmware) together with
//! drivecheck's own host shim — a ChibiOS/RT subset on one virtual CPU, HAL and board stand-ins,
//! and stand-ins for the hardware drivers — into a separate executable. The firmware's code is
//! never linked into drivecheck; [`SitlProcess`] runs that executable and speaks its framed
//! stdin/stdout protocol ([`protocol`], described in `docs/sitl.md`): advance virtual time, give
//! sensor inputs, take actuator outputs, and carry the car protocol's bytes both ways through
//! the firmware's own `packet.c` and `commands.c`.
//!
//! ```no_run
//! # fn run() -> Result<(), Box<dyn std::error::Error>> {
//! use std::path::Path;
//! let build = sitl::build(Path::new("/src/rise_sdvp/Embedded/RC_Controller"), Path::new("/tmp/sitl-cache"))?;
//! println!("firmware {}.{}: {} files, {} stubs", build.version.0, build.version.1,
//!     build.compiled.len(), build.stubbed.len());
//! let mut car = sitl::SitlProcess::start(&build.executable)?;
//! let outputs = car.advance_to(1_500_000)?; // 1.5 s of virtual time
//! # let _ = outputs; Ok(()) }
//! ```

mod builder;
mod process;
pub mod protocol;
pub mod variant;

pub use builder::{Build, BuildError, PORTABLE_SOURCES, build, shim_sources};
pub use process::{SitlError, SitlProcess};
