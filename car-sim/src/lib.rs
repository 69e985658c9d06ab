//! A simulated car and hardware-in-the-loop board that an orchestrator cannot tell from the
//! reference controller board: same behaviour, same quirks, both firmware generations (10.1, the
//! default, and 12.3).
//!
//! The core is [`SimCar`]: a deterministic model of the firmware's tasks stepped on a 10 ms tick —
//! the HIL motor simulator, steering servo, true vehicle motion, odometry and the RTK-fused
//! position, the pure-pursuit autopilot, UWB ranging against a [`World`] (line of sight,
//! reflections, blocking) with the UWB estimator of each era, fault injection with the exact
//! terminal texts, and the communication watchdog. It does no I/O and reads no clock: time passes
//! only through [`SimCar::step`], and every random draw comes from streams seeded by
//! [`CarOptions::seed`], so the same seed and the same commands give identical telemetry.
//!
//! ```
//! use car_sim::{SimCar, CarOptions, RoutePoint};
//!
//! let mut car = SimCar::new(CarOptions::default());
//! let route: Vec<RoutePoint> = (0..20).map(|i| RoutePoint::at(i as f32, 0.0, 2.0)).collect();
//! car.terminal("ping");
//! car.add_points(&route[..5]);
//! car.set_active(true, false);
//! for _ in 0..100 {
//!     car.step();
//!     if car.now_ms().is_multiple_of(100) {
//!         car.get_state(); // the orchestrator's poll keeps the watchdog quiet
//!     }
//! }
//! assert!(car.truth().x > 0.5);
//! ```
//!
//! Around the model, [`Board`] is the firmware's packet handler (requests decoded and replies
//! encoded with `car-link`, in the firmware's truncating dialect), and [`server`] runs a board as
//! an async task on tokio's clock: [`spawn_in_process`] (what `drivecheck run --car sim` uses; on a
//! paused clock it runs in virtual time, thousands of times faster than real time and
//! deterministic), [`serve_tcp`] (one client at a time, like the bridge) and [`serve_udp`], with
//! [`LinkImpairment`] on the simulator's side of the link.
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn std::error::Error>> {
//! let scenario = scenarios::bundled::load("parking-lot-2anchors")?.scenario;
//! let config = car_sim::SimConfig { seed: 7, ..car_sim::SimConfig::from_scenario(&scenario) };
//! let (stream, sim) = car_sim::spawn_in_process(&config);
//! let car = car_link::Car::over_stream(stream, car_link::LinkConfig::default()).await?;
//! println!("{} at {:?}", car.version(), sim.truth());
//! # Ok(()) }
//! ```
//!
//! What it is not: a physics engine (the motion is a kinematic bicycle model driven by the
//! firmware's own motor simulator), nor the protocol codec (that is `car-link`), nor the
//! `drivecheck sim` command line (the orchestrator maps its flags onto [`SimConfig`]).

pub mod autopilot;
pub mod car;
pub mod config;
pub mod debug;
pub mod fault;
pub mod motor;
pub mod noise;
pub mod plant;
pub mod positioning;
pub mod profile;
pub mod protocol;
pub mod route_following;
pub mod server;
pub mod servo;
pub mod terminal;
pub mod uwb;
pub mod world;

pub use autopilot::{FwPose, RoutePart, RoutePoint};
pub use car::{
    CarOptions, GnssCorrection, GnssModel, Placement, RcMode, SensorErrors, SimCar, StateReport,
    raw_imu_yaw,
};
pub use config::{ApTimeMode, FirmwareConfig, VehicleParams};
pub use debug::{DebugEvent, Truth};
pub use fault::{FaultInjection, FaultKind};
pub use profile::{CarProfile, ProfileError};
pub use protocol::Board;
pub use server::{
    FaultInjectionView, LinkImpairment, SimConfig, SimHandle, serve_tcp, serve_udp,
    spawn_in_process,
};
pub use uwb::{RadioModel, RangeResult};
pub use world::{RadioPath, Wall, World, WorldAnchor};

use car_link::FirmwareVersion;

/// A firmware the simulated car cannot be.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unsupported firmware {0:?}: the simulator is 10.1 or 12.3")]
pub struct UnknownFirmware(pub String);

/// The firmware version `text` names (`10.1`, `12.3`, or a generation's major alone), when the
/// simulated car can be it ([`FirmwareVersion::SIMULATED`]).
pub fn simulated_firmware(text: &str) -> Result<FirmwareVersion, UnknownFirmware> {
    text.parse::<FirmwareVersion>()
        .ok()
        .filter(|v| v.profile().simulated)
        .ok_or_else(|| UnknownFirmware(text.trim().to_string()))
}

#[cfg(test)]
mod acceptance;

#[cfg(test)]
mod conformance;
