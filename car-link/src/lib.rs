//! The car's wire protocol, its transports and an async client.
//!
//! `car-link` speaks the reference car firmware's binary packet protocol byte for byte: framing with
//! CRC-16/XMODEM ([`frame`]), typed payloads for both directions and both firmware generations ([`message`],
//! [`version`], [`encoding`], [`config`]), links over TCP, UDP, USB serial and an in-process pipe
//! ([`transport`], [`address`]), and an async [`client::Car`] that handshakes the firmware version, matches replies
//! to requests, retries, keeps the car's watchdog fed and reports link health ([`health`]). Fault injection
//! through terminal commands is typed in [`fault`].
//!
//! The same codec and message types serve the car side: a simulator decodes [`message::Request`]s and encodes
//! [`message::Reply`]s, with [`frame::FrameCodec::car`] on the car end of [`transport::sim_pipe`].
//!
//! ```no_run
//! # async fn drive() -> Result<(), car_link::client::CarError> {
//! use car_link::{CarAddress, Car, LinkConfig, RoutePoint};
//! let address: CarAddress = "tcp://192.168.1.20:8300".parse().expect("a valid address");
//! let car = Car::connect(&address, LinkConfig::default()).await?;
//! println!("firmware {}", car.version());
//! car.clear_route().await?;
//! car.add_points(&[RoutePoint::at(0.0, 0.0, 1.0), RoutePoint::at(5.0, 0.0, 1.0)]).await?;
//! car.set_autopilot(true, false).await?;
//! let sample = car.state().await?;
//! println!("at ({}, {}) at {} ms of day", sample.state.px, sample.state.py, sample.ms_today());
//! car.brake(50.0).await?;
//! # Ok(()) }
//! ```
//!
//! It is not a simulator (see `car-sim`), not a test orchestrator, and it does not speak the control station's
//! XML interface (`docs/protocol.md#what-car-link-does-not-speak`). It does not decide whether a car behaves correctly:
//! it only carries what the car says, and says when the link is lost instead of inventing a state.

pub mod address;
#[cfg(feature = "client")]
pub mod client;
pub mod config;
pub mod crc;
pub mod encoding;
pub mod fault;
pub mod firmware;
pub mod frame;
#[cfg(feature = "client")]
pub mod health;
pub mod message;
#[cfg(feature = "client")]
pub mod transport;
pub mod version;

pub use address::CarAddress;
#[cfg(feature = "client")]
pub use client::{Car, CarError, LinkConfig, LinkEvent, StatePolling, StateSample};
pub use fault::{FaultKind, Probe};
pub use firmware::FirmwareVersion;
pub use message::{CarState, Reply, Request, RoutePoint};
pub use version::CommandId;
