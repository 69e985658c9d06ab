//! The emergency stop of the cars a command drives: what the operator's second signal does
//! (the command line listens for the signals, `orchestrator/src/commands/signals.rs`). A command
//! registers the cars of its campaign ([`EmergencyStop::register`]) for as long as it drives
//! them; [`EmergencyStop::brake_now`] brakes every registered car at once, as the safe stop does,
//! and [`EmergencyStop::disarm_now`] then clears their faults and disables fault injection,
//! each within a limit short enough for the process to end soon after.

use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use car_link::CarError;

use crate::vehicle::Vehicle;

/// The brake current the emergency stop sends, as the runner's safe stop does.
pub const BRAKE_A: f64 = 50.0;

/// How long [`EmergencyStop::brake_now`] waits after the brake was queued, so that the link's
/// writer sends it (a brake has no reply; RC_CONTROL is fire and forget).
const BRAKE_FLUSH: Duration = Duration::from_millis(100);

/// At most this long for the brake to find room in the link's send queue; the car's 2 s watchdog
/// brakes it in any case once the process is gone.
const BRAKE_SEND_LIMIT: Duration = Duration::from_millis(500);

/// At most this long, after the brake, for the cars to clear their faults and disable fault
/// injection (the runner's own session end does not come: the process is about to end).
pub const DISARM_LIMIT: Duration = Duration::from_millis(400);

/// The registered cars' brake: clones of the cars, braking with the current given.
type Brake = Box<dyn Fn(f64) -> Pin<Box<dyn Future<Output = Result<(), CarError>> + Send>> + Send>;

/// The registered cars' disarming within the time given; what could not be done, a warning per
/// car.
type Disarm = Box<dyn Fn(Duration) -> Pin<Box<dyn Future<Output = Vec<String>> + Send>> + Send>;

/// What the emergency stop does to the registered cars.
struct Registered {
    brake: Brake,
    disarm: Disarm,
}

/// Where the registered cars are.
type Slot = Arc<Mutex<Option<Registered>>>;

/// The emergency stop of the cars registered with it (see the module doc). Clones share the
/// registration.
#[derive(Clone, Default)]
pub struct EmergencyStop {
    registered: Slot,
    /// How many cars are registered (several: the operator is told "every car").
    cars: Arc<AtomicUsize>,
}

impl std::fmt::Debug for EmergencyStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmergencyStop")
            .field("registered", &lock(&self.registered).is_some())
            .finish()
    }
}

impl EmergencyStop {
    /// Registers `cars` (the cars of one campaign, braked at once) until the returned guard is
    /// dropped (a registered car keeps its link, and so its keepalive, alive).
    pub fn register<V: Vehicle>(&self, cars: &[V]) -> Registration {
        self.cars.store(cars.len(), Ordering::SeqCst);
        let cars = cars.to_vec();
        let several = cars.len() > 1;
        let to_disarm = cars.clone();
        let brake: Brake = Box::new(move |current_a| {
            let cars = cars.clone();
            Box::pin(async move {
                let braked =
                    futures::future::join_all(cars.iter().map(|car| car.brake(current_a))).await;
                braked
                    .into_iter()
                    .collect::<Result<Vec<()>, CarError>>()
                    .map(drop)
            })
        });
        let disarm: Disarm = Box::new(move |limit| {
            let cars = to_disarm.clone();
            Box::pin(async move {
                let disarmed =
                    futures::future::join_all(cars.iter().map(|car| crate::disarm(car, limit)))
                        .await;
                disarmed
                    .into_iter()
                    .enumerate()
                    .filter_map(|(k, result)| result.err().map(|e| (k, e)))
                    .map(|(k, error)| match several {
                        true => format!("car {}: {error}", k + 1),
                        false => error.to_string(),
                    })
                    .collect()
            })
        });
        *lock(&self.registered) = Some(Registered { brake, disarm });
        Registration {
            registered: Arc::clone(&self.registered),
        }
    }

    /// How many cars the last registration holds.
    pub fn cars(&self) -> usize {
        self.cars.load(Ordering::SeqCst)
    }

    /// Brakes the registered cars, if any, and gives the link a moment to send the command.
    /// What went wrong, if anything, to tell the operator.
    pub async fn brake_now(&self) -> Option<String> {
        let braking = lock(&self.registered)
            .as_ref()
            .map(|registered| (registered.brake)(BRAKE_A))?;
        match tokio::time::timeout(BRAKE_SEND_LIMIT, braking).await {
            Ok(Ok(())) => {
                tokio::time::sleep(BRAKE_FLUSH).await;
                None
            }
            Ok(Err(error)) => Some(format!("cannot brake: {error}")),
            Err(_) => Some("cannot brake: the link's send queue stayed full".to_owned()),
        }
    }

    /// Clears the registered cars' faults and disables their fault injection, within
    /// [`DISARM_LIMIT`]: a warning for each car that could not be.
    pub async fn disarm_now(&self) -> Vec<String> {
        let disarming = lock(&self.registered)
            .as_ref()
            .map(|registered| (registered.disarm)(DISARM_LIMIT));
        match disarming {
            Some(disarming) => disarming.await,
            None => Vec::new(),
        }
    }
}

/// While it lives, the cars registered with [`EmergencyStop::register`] are the ones it stops.
pub struct Registration {
    registered: Slot,
}

impl std::fmt::Debug for Registration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registration").finish_non_exhaustive()
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        *lock(&self.registered) = None;
    }
}

/// The slot's cars, whether or not a thread panicked while holding it.
fn lock(slot: &Mutex<Option<Registered>>) -> std::sync::MutexGuard<'_, Option<Registered>> {
    slot.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::connect_sim;
    use car_link::RoutePoint;

    /// Drives the embedded simulated car on its autopilot at 1.5 m/s for 3 s (a straight route
    /// onward from where it stands, along the scenario's start route), then, when `brake`,
    /// registers it with an emergency stop and brakes as the second signal does; the car's speed 0.5 s
    /// later.
    async fn speed_after(brake: bool) -> f64 {
        let scenario = scenarios::bundled::load("parking-lot-2anchors")
            .expect("bundled")
            .scenario;
        let (car, sim) = connect_sim(&car_sim::SimConfig::from_scenario(&scenario))
            .await
            .expect("the simulated car");
        let start = scenario.start_route.positions();
        let (from, to) = (start[0], start[1]);
        let (dx, dy) = (to.x - from.x, to.y - from.y);
        let step = 2.0 / dx.hypot(dy);
        let route: Vec<RoutePoint> = (1..=15)
            .map(|k| {
                let k = f64::from(k) * step;
                RoutePoint::at(from.x + k * dx, from.y + k * dy, 1.5)
            })
            .collect();
        car.clear_route().await.expect("cleared");
        car.add_points(&route).await.expect("uploaded");
        car.set_autopilot(true, false).await.expect("started");
        tokio::time::sleep(Duration::from_secs(3)).await;
        assert!(sim.truth().speed > 1.0, "the car drives: {:?}", sim.truth());
        let stop = EmergencyStop::default();
        let guard = stop.register(std::slice::from_ref(&car));
        if brake {
            assert_eq!(stop.brake_now().await, None, "braked");
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(guard);
        assert!(
            lock(&stop.registered).is_none(),
            "the guard unregisters the car"
        );
        sim.truth().speed
    }

    #[tokio::test(start_paused = true)]
    async fn the_second_signal_brakes_the_registered_car() {
        let coasting = speed_after(false).await;
        let braked = speed_after(true).await;
        assert!(
            coasting > 1.0,
            "without the brake it still drives: {coasting}"
        );
        assert!(braked < 0.3, "the brake stops it: {braked}");
    }
}
