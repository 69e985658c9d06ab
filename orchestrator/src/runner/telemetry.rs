//! State samples at a fixed rate, polled by a task of their own so that a slow command never
//! delays them.
//!
//! GET_STATE requests are one at a time on the link (replies carry no request id), so a sample
//! cannot come faster than one round trip. A request without a reply within the sample timeout
//! is dropped (car-link discards its late reply as stray) and the next tick asks again.
//!
//! Every sample taken from the channel (also one thrown away by [`Telemetry::drain`]) is
//! recorded in the campaign's journal.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use car_link::{Car, CarError, StateSample};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::MissedTickBehavior;

use super::journal::Journal;

/// One item of the telemetry.
#[derive(Debug, Clone)]
pub(crate) enum Sample {
    /// A state.
    State(Box<StateSample>),
    /// The link is lost.
    LinkLost,
}

/// The sampling task and its channel; dropping it stops the task.
#[derive(Debug)]
pub(crate) struct Telemetry {
    rx: mpsc::Receiver<Sample>,
    task: JoinHandle<()>,
    unanswered: Arc<AtomicU64>,
}

impl Telemetry {
    /// Starts polling `car` every `period`, each request bounded by `timeout`.
    pub(crate) fn start(car: &Car, period: Duration, timeout: Duration) -> Self {
        let (tx, rx) = mpsc::channel(1);
        let unanswered = Arc::new(AtomicU64::new(0));
        let task = tokio::spawn(poll(car.clone(), period, timeout, tx, unanswered.clone()));
        Self {
            rx,
            task,
            unanswered,
        }
    }

    /// State requests that got no answer in time so far (a sign of a lossy link).
    pub(crate) fn unanswered(&self) -> u64 {
        self.unanswered.load(Ordering::Relaxed)
    }

    /// The next sample, recorded in `journal`; `LinkLost` also once the task has ended.
    /// Cancel-safe.
    pub(crate) async fn next(&mut self, journal: &Journal<'_>) -> Sample {
        let sample = self.rx.recv().await.unwrap_or(Sample::LinkLost);
        if let Sample::State(state) = &sample {
            journal.state(state);
        }
        sample
    }

    /// Throws away (after recording it in `journal`) a sample that waited while nobody
    /// listened (call before a drive loop).
    pub(crate) fn drain(&mut self, journal: &Journal<'_>) {
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

async fn poll(
    car: Car,
    period: Duration,
    timeout: Duration,
    tx: mpsc::Sender<Sample>,
    unanswered: Arc<AtomicU64>,
) {
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    loop {
        ticker.tick().await;
        let sample = match tokio::time::timeout(timeout, car.state()).await {
            Ok(Ok(state)) => Sample::State(Box::new(state)),
            Ok(Err(CarError::LinkLost)) => Sample::LinkLost,
            Ok(Err(_)) | Err(_) => {
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
