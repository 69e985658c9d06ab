//! The signals of every command, and the async runtime of a command that drives a car.
//!
//! From the start of the process one thread listens for SIGINT (Ctrl-C), SIGTERM and SIGHUP
//! ([`listen_for_the_process`]; SIGHUP not when it was ignored as drivecheck started, as `nohup`
//! ignores it). A command that handles them itself subscribes ([`subscribe`]):
//! a command that drives a car (the first signal cancels the campaign, the runner ends the test
//! with its safe stop and the session with the car disarmed; the second brakes every registered
//! car at once and disarms it: its faults cleared, fault injection disabled), `sim` (a signal
//! stops the simulated car). While no command subscribes (a command that only reads and writes
//! files: `report`, `runs merge`, `explain`, `compare`, …) a signal ends the process at once,
//! its scratch files removed (`runner::scratch`), with status 2 and `error: interrupted (SIGINT)`
//! (`crate::process::interrupted`). Also here: the embedded simulator's debug view the runner
//! records.

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use car_sim::SimHandle;
use tokio_util::sync::CancellationToken;

use car_link::CarError;
use runner::vehicle::SimulatorView;
use runner::vehicle::Vehicle;

use crate::output;

/// The async runtime: on one thread with a paused clock (virtual time, the embedded simulated
/// car) or on two threads against the wall clock.
pub fn runtime(virtual_time: bool) -> Result<tokio::runtime::Runtime> {
    let runtime = if virtual_time {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .start_paused(true)
            .build()
    } else {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
    };
    runtime.context("cannot start the async runtime")
}

/// The debug view of `sim`, if the car is the embedded simulator.
pub(super) fn sim_view(sim: &Option<SimHandle>) -> Option<&dyn SimulatorView> {
    sim.as_ref().map(|sim| sim as &dyn SimulatorView)
}

/// A token cancelled at the first SIGINT (Ctrl-C), SIGTERM (`timeout`, systemd, a cancelled CI
/// job) or SIGHUP (a closed terminal): the runner then stops the car safely, records the running
/// test as aborted (`interrupted`), completes the run directory and the recording, and the command
/// exits with status 2. A second signal brakes the car registered with
/// [`Interrupt::brake_on_second`] at once, ends the test in flight there (aborted, the hard brake
/// named in its case) and the process with status 2 within half a second. Call it inside the
/// runtime.
pub(super) fn cancel_on_ctrl_c() -> CancellationToken {
    Interrupt::listen().cancel
}

/// The interrupt path of a command that drives (see [`cancel_on_ctrl_c`]): the token the first
/// signal cancels, and the car the second signal brakes.
#[derive(Clone)]
pub(super) struct Interrupt {
    cancel: CancellationToken,
    car: Slot,
    /// How many cars the second signal brakes (several: the first signal's message says so).
    cars: Arc<std::sync::atomic::AtomicUsize>,
}

/// The registered car's brake: a clone of the car, braking with the current given.
type Brake = Box<dyn Fn(f64) -> Pin<Box<dyn Future<Output = Result<(), CarError>> + Send>> + Send>;

/// The registered cars' session end: their faults cleared and fault injection disabled within
/// the time given; what could not be done, a warning per car.
type Disarm = Box<dyn Fn(Duration) -> Pin<Box<dyn Future<Output = Vec<String>> + Send>> + Send>;

/// What the second signal does to the registered cars.
struct Registered {
    brake: Brake,
    disarm: Disarm,
}

/// Where the car the second signal brakes is registered.
type Slot = Arc<Mutex<Option<Registered>>>;

impl std::fmt::Debug for Interrupt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Interrupt")
            .field("cancel", &self.cancel)
            .field("registered", &lock(&self.car).is_some())
            .finish()
    }
}

/// The brake the second signal sends, as the runner's safe stop does.
const SECOND_SIGNAL_BRAKE_A: f64 = 50.0;

/// How long the process lives after the second signal's brake was queued, so that the link's
/// writer sends it (a brake has no reply; RC_CONTROL is fire and forget).
const BRAKE_FLUSH: Duration = Duration::from_millis(100);

/// How long the process lives after the second signal's brake for the runner to write the test
/// in flight and complete the run directory.
const HARD_STOP_GRACE: Duration = Duration::from_millis(500);

/// At most this long for the brake to find room in the link's send queue; the car's 2 s watchdog
/// brakes it in any case once the process is gone.
const BRAKE_SEND_LIMIT: Duration = Duration::from_millis(500);

/// At most this long, after the second signal's brake, for the cars to clear their faults and
/// disable fault injection (the runner does not: the process is about to end).
const DISARM_LIMIT: Duration = Duration::from_millis(400);

impl Interrupt {
    /// Listens for SIGINT, SIGTERM and SIGHUP from now on ([`subscribe`]: a signal that comes
    /// before the runtime runs the listener waits for it). Call it inside the runtime.
    pub(super) fn listen() -> Self {
        let interrupt = Self {
            cancel: CancellationToken::new(),
            car: Arc::new(Mutex::new(None)),
            cars: Arc::default(),
        };
        let listener = interrupt.clone();
        let mut signals = subscribe();
        tokio::spawn(async move {
            let Some(first) = signals.recv().await else {
                return;
            };
            let cars = match listener.cars.load(std::sync::atomic::Ordering::SeqCst) {
                0 | 1 => "the car",
                _ => "every car",
            };
            output::safety(format_args!(
                "{first}: stopping {cars} safely (send it again to brake at once and exit)"
            ));
            listener.cancel.cancel();
            let Some(second) = signals.recv().await else {
                return;
            };
            output::safety(format_args!("{second} again: braking at once and exiting"));
            listener.brake_now().await;
            listener.disarm_now().await;
            // The test in flight ends at once, aborted; its case, campaign.json and the recording
            // are written in the half second the process still lives (a command that completes
            // sooner exits sooner); then the scratch files still being written are removed.
            runner::hard_stop().cancel();
            tokio::time::sleep(HARD_STOP_GRACE).await;
            let _held = runner::scratch::remove_all();
            crate::exit::Exit::Error.exit();
        });
        interrupt
    }

    /// The token the first signal cancels.
    pub(super) fn token(&self) -> &CancellationToken {
        &self.cancel
    }

    /// Registers `car` as the one the second signal brakes, until the returned guard is dropped
    /// (a registered car keeps its link, and so its keepalive, alive).
    pub(super) fn brake_on_second<V: Vehicle>(&self, car: &V) -> BrakeOnSecond {
        self.brake_all_on_second(std::slice::from_ref(car))
    }

    /// [`Interrupt::brake_on_second`] for every car of a campaign on several cars, braked at
    /// once.
    pub(super) fn brake_all_on_second<V: Vehicle>(&self, cars: &[V]) -> BrakeOnSecond {
        self.cars
            .store(cars.len(), std::sync::atomic::Ordering::SeqCst);
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
                    futures::future::join_all(cars.iter().map(|car| runner::disarm(car, limit)))
                        .await;
                disarmed
                    .into_iter()
                    .enumerate()
                    .filter_map(|(k, result)| result.err().map(|e| (k, e)))
                    .map(|(k, error)| {
                        if several {
                            format!("car {}: {error}", k + 1)
                        } else {
                            error.to_string()
                        }
                    })
                    .collect()
            })
        });
        *lock(&self.car) = Some(Registered { brake, disarm });
        BrakeOnSecond {
            car: Arc::clone(&self.car),
        }
    }

    /// Brakes the registered car, if any, and gives the link a moment to send the command.
    async fn brake_now(&self) {
        let Some(braking) = lock(&self.car)
            .as_ref()
            .map(|registered| (registered.brake)(SECOND_SIGNAL_BRAKE_A))
        else {
            return;
        };
        match tokio::time::timeout(BRAKE_SEND_LIMIT, braking).await {
            Ok(Ok(())) => tokio::time::sleep(BRAKE_FLUSH).await,
            Ok(Err(error)) => output::safety(format_args!("cannot brake: {error}")),
            Err(_) => output::safety("cannot brake: the link's send queue stayed full"),
        }
    }
}

impl Interrupt {
    /// Clears the registered cars' faults and disables their fault injection, within
    /// [`DISARM_LIMIT`]; says on standard error which could not be.
    async fn disarm_now(&self) {
        let Some(disarming) = lock(&self.car)
            .as_ref()
            .map(|registered| (registered.disarm)(DISARM_LIMIT))
        else {
            return;
        };
        for warning in disarming.await {
            output::safety(format_args!("warning: {warning}"));
        }
    }
}

/// While it lives, the second signal brakes the car registered with
/// [`Interrupt::brake_on_second`].
pub(super) struct BrakeOnSecond {
    car: Slot,
}

impl std::fmt::Debug for BrakeOnSecond {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BrakeOnSecond").finish_non_exhaustive()
    }
}

impl Drop for BrakeOnSecond {
    fn drop(&mut self) {
        *lock(&self.car) = None;
    }
}

/// The slot's car, whether or not a thread panicked while holding it.
fn lock(slot: &Mutex<Option<Registered>>) -> std::sync::MutexGuard<'_, Option<Registered>> {
    slot.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A command that handles signals itself stopped at one before its end (exit status 2, as every
/// interrupted command): what it did not finish.
#[derive(Debug, thiserror::Error)]
#[error("interrupted by a signal: {0}")]
pub(crate) struct Interrupted(pub &'static str);

/// The subscribers to the signals: the commands handling them now ([`subscribe`]).
static SUBSCRIBERS: Mutex<Vec<tokio::sync::mpsc::UnboundedSender<&'static str>>> =
    Mutex::new(Vec::new());

/// The signals from now on, each as its name (`interrupted (SIGINT)`, `terminated (SIGTERM)`,
/// `hung up (SIGHUP)`), until the receiver is dropped: while a command holds one, a signal is
/// its to handle (see the module doc). A signal that comes before the receiver is read waits in
/// it.
pub(crate) fn subscribe() -> tokio::sync::mpsc::UnboundedReceiver<&'static str> {
    listen_for_the_process();
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    SUBSCRIBERS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .push(tx);
    rx
}

/// Starts the process's one listener for SIGINT, SIGTERM and SIGHUP (once; later calls do
/// nothing), and returns when the signals are its: from then on a signal hands each to the
/// commands that [`subscribe`], or, while none does, ends the process
/// (`crate::process::interrupted`).
pub(crate) fn listen_for_the_process() {
    static STARTED: std::sync::Once = std::sync::Once::new();
    STARTED.call_once(|| {
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("signals".to_owned())
            .spawn(move || {
                let runtime = match tokio::runtime::Builder::new_current_thread()
                    .enable_io()
                    .build()
                {
                    Ok(runtime) => runtime,
                    Err(error) => {
                        let _ = ready_tx.send(Err(error.to_string()));
                        return;
                    }
                };
                runtime.block_on(async move {
                    let mut signals = Signals::new();
                    let _ = ready_tx.send(Ok(()));
                    loop {
                        let name = signals.next().await;
                        runner::note_signal();
                        if !hand_over(name) {
                            crate::process::interrupted(name);
                        }
                    }
                });
            });
        let started = match spawned {
            Ok(_) => ready_rx
                .recv()
                .unwrap_or_else(|_| Err("its thread ended".to_owned())),
            Err(error) => Err(error.to_string()),
        };
        if let Err(error) = started {
            output::warning(format_args!(
                "signals are not handled (cannot listen for them: {error}): a signal ends \
                 drivecheck at once"
            ));
        }
    });
}

/// Hands the signal `name` to every command that subscribed and still listens; whether one did.
fn hand_over(name: &'static str) -> bool {
    let mut subscribers = SUBSCRIBERS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    subscribers.retain(|tx| tx.send(name).is_ok());
    !subscribers.is_empty()
}

/// Says which scratch files of processes that no longer run were removed
/// (`runner::scratch::clear_leftovers`).
pub(crate) fn note_leftovers(removed: Vec<runner::scratch::Leftover>) {
    for leftover in removed {
        output::note(format_args!(
            "removed {}: left by process {}, which no longer runs",
            leftover.path.display(),
            leftover.pid
        ));
    }
}

/// Whether SIGHUP was ignored when drivecheck started (`nohup drivecheck …`): then it stays
/// ignored, as `nohup` asks (Linux: the `SigIgn` mask of `/proc/self/status`; elsewhere it is
/// handled).
fn hangup_ignored() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            status
                .lines()
                .find_map(|line| line.strip_prefix("SigIgn:"))
                .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        })
        .is_some_and(|mask| mask & 1 != 0)
}

/// The signals that stop a command: SIGINT, and on Unix SIGTERM and SIGHUP (unless ignored
/// when drivecheck started: [`hangup_ignored`]).
struct Signals {
    #[cfg(unix)]
    int: Option<tokio::signal::unix::Signal>,
    #[cfg(unix)]
    term: Option<tokio::signal::unix::Signal>,
    #[cfg(unix)]
    hup: Option<tokio::signal::unix::Signal>,
}

impl Signals {
    fn new() -> Self {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            Self {
                int: signal(SignalKind::interrupt()).ok(),
                term: signal(SignalKind::terminate()).ok(),
                hup: (!hangup_ignored())
                    .then(|| signal(SignalKind::hangup()).ok())
                    .flatten(),
            }
        }
        #[cfg(not(unix))]
        {
            Self {}
        }
    }

    /// Waits for the next signal; its name.
    async fn next(&mut self) -> &'static str {
        #[cfg(unix)]
        {
            async fn on(signal: &mut Option<tokio::signal::unix::Signal>) {
                match signal {
                    Some(signal) => {
                        signal.recv().await;
                    }
                    None => std::future::pending().await,
                }
            }
            tokio::select! {
                () = on(&mut self.int) => "interrupted (SIGINT)",
                () = on(&mut self.term) => "terminated (SIGTERM)",
                () = on(&mut self.hup) => "hung up (SIGHUP)",
            }
        }
        #[cfg(not(unix))]
        {
            if tokio::signal::ctrl_c().await.is_err() {
                std::future::pending::<()>().await;
            }
            "interrupted"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use car_link::RoutePoint;
    use runner::vehicle::connect_sim;

    /// Drives the embedded simulated car on its autopilot at 1.5 m/s for 3 s (a straight route
    /// onward from where it stands, along the scenario's start route), then, when `brake`,
    /// registers it with an interrupt and brakes as the second signal does; the car's speed 0.5 s
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
        let interrupt = Interrupt {
            cancel: CancellationToken::new(),
            car: Arc::new(Mutex::new(None)),
            cars: Arc::default(),
        };
        let guard = interrupt.brake_on_second(&car);
        if brake {
            interrupt.brake_now().await;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(guard);
        assert!(
            lock(&interrupt.car).is_none(),
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
