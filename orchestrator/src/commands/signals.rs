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

use std::sync::Mutex;
use std::time::Duration;

use anyhow::{Context, Result};
use car_sim::SimHandle;
use tokio_util::sync::CancellationToken;

use runner::emergency::{EmergencyStop, Registration};
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
/// signal cancels, and the cars the second signal brakes and disarms (`runner::emergency`).
#[derive(Clone, Debug)]
pub(super) struct Interrupt {
    cancel: CancellationToken,
    stop: EmergencyStop,
}

/// How long the process lives after the second signal's brake for the runner to write the test
/// in flight and complete the run directory.
const HARD_STOP_GRACE: Duration = Duration::from_millis(500);

impl Interrupt {
    /// Listens for SIGINT, SIGTERM and SIGHUP from now on ([`subscribe`]: a signal that comes
    /// before the runtime runs the listener waits for it). Call it inside the runtime.
    pub(super) fn listen() -> Self {
        let interrupt = Self {
            cancel: CancellationToken::new(),
            stop: EmergencyStop::default(),
        };
        let listener = interrupt.clone();
        let mut signals = subscribe();
        tokio::spawn(async move {
            let Some(first) = signals.recv().await else {
                return;
            };
            let cars = match listener.stop.cars() {
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
            if let Some(problem) = listener.stop.brake_now().await {
                output::safety(problem);
            }
            for warning in listener.stop.disarm_now().await {
                output::safety(format_args!("warning: {warning}"));
            }
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
    pub(super) fn brake_on_second<V: Vehicle>(&self, car: &V) -> Registration {
        self.stop.register(std::slice::from_ref(car))
    }

    /// [`Interrupt::brake_on_second`] for every car of a campaign on several cars, braked at
    /// once.
    pub(super) fn brake_all_on_second<V: Vehicle>(&self, cars: &[V]) -> Registration {
        self.stop.register(cars)
    }
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
