//! The benchmarks, one module each (`drivecheck-dev bench …`).

pub mod agreement;
pub mod compare;
pub mod compare_firmware;
pub mod fidelity;
mod fidelity_route;
pub mod generator;
pub mod kill_resume;
pub mod placement;
pub mod recovery;
pub mod scale;
pub mod twin_reach;
