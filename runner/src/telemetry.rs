//! State samples at a fixed rate, polled by a task of their own so that a slow command never
//! delays them.
//!
//! The task runs the car's pipelined state stream ([`Vehicle::poll_states`], for a RISE car
//! car-link's): a GET_STATE request every state period without waiting for the replies, as many
//! in flight as the sample timeout needs, so that on a link whose round trip is longer than the
//! period a sample still comes every period. A request without a reply within the sample timeout counts as unanswered (a
//! sign of a lossy link); the requests after it are not held up.
//!
//! The task polls all the time, also while nobody listens (between the drive loops): when a loop
//! starts, and its safety monitor starts counting staleness, samples are then already coming
//! every period, instead of one round trip after the first request. Samples wait in the channel
//! (up to [`BUFFERED`] of them) until a loop takes them or [`Telemetry::drain`] records and
//! discards them; only a channel full for that long pauses the polling.
//!
//! Every sample taken from the channel (also one thrown away by [`Telemetry::drain`]) is
//! recorded in the campaign's journal.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use car_link::{CarError, StatePolling, StateSample};
use futures::StreamExt;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::journal::Journal;
use crate::vehicle::Vehicle;

/// How much telemetry waits in the channel while nobody listens before the polling pauses.
const BUFFERED: Duration = Duration::from_secs(60);

/// One item of the telemetry.
#[derive(Debug, Clone)]
pub enum Sample {
    /// A state.
    State(Box<StateSample>),
    /// The link is lost.
    LinkLost,
}

/// The sampling task and its channel; dropping it stops the task.
#[derive(Debug)]
pub struct Telemetry {
    rx: mpsc::Receiver<Sample>,
    task: JoinHandle<()>,
    unanswered: Arc<AtomicU64>,
}

impl Telemetry {
    /// Starts polling `car` every `period`, each request bounded by `timeout` (with up to
    /// `ceil(timeout / period)` requests in flight).
    pub fn start<V: Vehicle>(car: &V, period: Duration, timeout: Duration) -> Self {
        let capacity = BUFFERED.as_nanos() / period.max(Duration::from_millis(1)).as_nanos();
        let capacity = usize::try_from(capacity).unwrap_or(4096).clamp(16, 4096);
        let (tx, rx) = mpsc::channel(capacity);
        let unanswered = Arc::new(AtomicU64::new(0));
        let task = tokio::spawn(poll(car.clone(), period, timeout, tx, unanswered.clone()));
        Self {
            rx,
            task,
            unanswered,
        }
    }

    /// State requests that got no answer in time so far (a sign of a lossy link).
    pub fn unanswered(&self) -> u64 {
        self.unanswered.load(Ordering::Relaxed)
    }

    /// The next sample, recorded in `journal`; `LinkLost` also once the task has ended.
    /// Cancel-safe.
    pub async fn next(&mut self, journal: &Journal<'_>) -> Sample {
        let sample = self.rx.recv().await.unwrap_or(Sample::LinkLost);
        if let Sample::State(state) = &sample {
            journal.state(state);
        }
        sample
    }

    /// Throws away (after recording them in `journal`) the samples that waited while nobody
    /// listened (call before a drive loop).
    pub fn drain(&mut self, journal: &Journal<'_>) {
        while let Ok(sample) = self.rx.try_recv() {
            if let Sample::State(state) = &sample {
                journal.state(state);
            }
        }
    }
}

impl Drop for Telemetry {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn poll<V: Vehicle>(
    car: V,
    period: Duration,
    timeout: Duration,
    tx: mpsc::Sender<Sample>,
    unanswered: Arc<AtomicU64>,
) {
    let states = car.poll_states(StatePolling::new(period, timeout));
    futures::pin_mut!(states);
    while let Some(item) = states.next().await {
        let sample = match item {
            Ok(state) => Sample::State(Box::new(state)),
            Err(CarError::LinkLost) => Sample::LinkLost,
            Err(_) => {
                unanswered.fetch_add(1, Ordering::Relaxed);
                continue;
            }
        };
        let lost = matches!(sample, Sample::LinkLost);
        if tx.send(sample).await.is_err() || lost {
            return;
        }
    }
}
