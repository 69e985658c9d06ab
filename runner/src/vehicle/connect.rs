//! Where a [`Vehicle`] comes from: the one place that builds a concrete car from what the user
//! named. A `tcp://`, `udp://` or serial address is a RISE car over `car-link`'s client; `sim` is
//! the embedded simulated car (`car-sim`) behind the same client, in process; [`EmbeddedSims`]
//! makes the fresh simulated car of every test of a campaign on the embedded simulator.
//!
//! Everything else sees the trait only: [`connect`] and [`connect_sim`] return `impl Vehicle`.

use std::time::Duration;

use car_link::{Car, CarAddress, CarError, LinkConfig};
use car_sim::SimHandle;
use thiserror::Error;

use super::{Connecting, FreshCars, SimulatorView, StartPose, Vehicle};
use campaign::seed::Purpose;

/// A car that could not be connected.
#[derive(Debug, Error)]
pub enum ConnectError {
    /// The car at an address.
    #[error("cannot connect to the car at {address}")]
    Car {
        /// The address as the user gave it.
        address: CarAddress,
        /// The link's error.
        source: CarError,
    },
    /// The embedded simulated car.
    #[error("cannot connect to the embedded simulated car")]
    Sim(#[source] CarError),
    /// The car's own firmware built for the host.
    #[error(transparent)]
    Sitl(#[from] super::sitl::SitlCarError),
}

/// How the runner talks to any car: round trips on a radio link can exceed the 250 ms default,
/// and a lossy one (30 % each way) loses about half the round trips, so an acked request gets 10
/// tries (all lost together about once in a thousand).
pub(super) fn car_config() -> LinkConfig {
    LinkConfig {
        request_timeout: Duration::from_secs(1),
        terminal_timeout: Duration::from_secs(2),
        tries: 10,
        ..LinkConfig::default()
    }
}

/// The car at `address`; for `sim` a fresh embedded simulated car, `sim` (a scenario's car, with
/// its profile applied) seeded with `seed`, with its handle (its debug view and its shutdown).
///
/// Timeout: the link's connection timeout and the version handshake's tries.
pub async fn connect(
    address: &CarAddress,
    sim: &car_sim::SimConfig,
    seed: u64,
) -> Result<(impl Vehicle + use<>, Option<SimHandle>), ConnectError> {
    if *address != CarAddress::Sim {
        let car = Car::connect(address, car_config())
            .await
            .map_err(|source| ConnectError::Car {
                address: address.clone(),
                source,
            })?;
        return Ok((car, None));
    }
    let (car, sim) = sim_car(&recorded_sim(sim, seed)).await?;
    Ok((car, Some(sim)))
}

/// A fresh embedded simulated car with `config`, with its handle.
pub async fn connect_sim(
    config: &car_sim::SimConfig,
) -> Result<(impl Vehicle + use<>, SimHandle), ConnectError> {
    sim_car(config).await
}

/// A fresh simulated car in the world of `config`, standing where it says, seeded as it says:
/// the embedded simulated car, or with `firmware` the car's own firmware built for the host
/// driving the same physical car (`car_sim::plant`); with its debug view, which stops the car
/// when dropped. What `shrink`, `sweep`, `explain --score`, `twin` and `calibrate` drive a case
/// on ([`crate::simdrive::SimDriver`]).
pub async fn connect_fresh(
    config: &car_sim::SimConfig,
    firmware: Option<&super::sitl::HostFirmware>,
) -> Result<(impl Vehicle + use<>, Box<dyn SimulatorView + Send>), ConnectError> {
    match firmware {
        None => {
            let (car, sim) = sim_car(config).await?;
            Ok((car, Box::new(sim) as Box<dyn SimulatorView + Send>))
        }
        Some(firmware) => {
            let car = super::sitl::SitlCar {
                executable: firmware.executable.clone(),
                plant: super::sitl::plant_options(firmware, config),
            };
            // Fresh cars run in virtual time: the thread and the firmware share a core.
            super::sitl::share_a_core_with_the_firmware();
            let (car, handle) = super::sitl::connect_sitl(&car).await?;
            Ok((car, Box::new(handle) as Box<dyn SimulatorView + Send>))
        }
    }
}

/// [`connect_sim`], as the concrete car.
async fn sim_car(config: &car_sim::SimConfig) -> Result<(Car, SimHandle), ConnectError> {
    let (stream, sim) = car_sim::spawn_in_process(config);
    let car = Car::over_stream(stream, car_config())
        .await
        .map_err(ConnectError::Sim)?;
    Ok((car, sim))
}

/// The car behind `stream` with the link the runner gives a car ([`car_config`]): for tests that
/// put something between the embedded simulated car's pipe and the client (a proxy that changes
/// its replies).
#[cfg(test)]
pub(crate) async fn over_stream<S>(stream: S) -> Result<impl Vehicle + use<S>, ConnectError>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + 'static,
{
    Car::over_stream(stream, car_config())
        .await
        .map_err(ConnectError::Sim)
}

/// The simulated car `sim` seeded with `seed`, its debug events on: they are recorded on the
/// `/sim/…` channels of the campaign's MCAP (ranges, fault applications, watchdog).
fn recorded_sim(sim: &car_sim::SimConfig, seed: u64) -> car_sim::SimConfig {
    car_sim::SimConfig {
        seed,
        record_events: true,
        ..sim.clone()
    }
}

/// The simulated cars of a campaign with a fresh car per test (`run` on the embedded simulator):
/// test *i*'s car is seeded from the campaign's seed and *i*, and stands where the runner says.
pub struct EmbeddedSims {
    /// The simulator of the scenario, with the campaign's seed.
    config: car_sim::SimConfig,
    /// Virtual time (the default) or the wall clock (`--realtime`, `--live`).
    virtual_time: bool,
}

impl EmbeddedSims {
    /// The cars of a campaign with `seed`, each the simulated car `sim` (a scenario's car with
    /// its profile applied).
    pub fn new(sim: &car_sim::SimConfig, seed: u64, virtual_time: bool) -> Self {
        Self::with_config(recorded_sim(sim, seed), virtual_time)
    }

    /// The cars of a campaign on simulators configured as `config` (its seed the campaign's).
    pub fn with_config(config: car_sim::SimConfig, virtual_time: bool) -> Self {
        Self {
            config,
            virtual_time,
        }
    }
}

impl FreshCars for EmbeddedSims {
    type Vehicle = Car;

    fn virtual_time(&self) -> bool {
        self.virtual_time
    }

    fn connect(&self, test_index: usize, start: Option<StartPose>) -> Connecting<'_, Car> {
        let config = placed(
            car_sim::SimConfig {
                seed: campaign::seed::derive(self.config.seed, Purpose::Simulator { test_index }),
                ..self.config.clone()
            },
            start,
        );
        Box::pin(async move {
            let (car, sim) = sim_car(&config).await?;
            Ok((car, Box::new(sim) as Box<dyn SimulatorView>))
        })
    }
}

/// The simulated car `config` standing at `start` when it starts (`None`: where `config` puts
/// it, the start of the scenario's start route unless it says otherwise).
pub fn placed(mut config: car_sim::SimConfig, start: Option<StartPose>) -> car_sim::SimConfig {
    if let Some(start) = start {
        config.placement = Some(car_sim::Placement {
            x: start.position.x,
            y: start.position.y,
            heading: start.heading,
        });
    }
    config
}

/// The embedded simulator's debug view, as the runner records it.
impl SimulatorView for SimHandle {
    fn truth(&self) -> car_sim::Truth {
        SimHandle::truth(self)
    }

    fn take_events(&self) -> Vec<car_sim::DebugEvent> {
        SimHandle::take_events(self)
    }
}
