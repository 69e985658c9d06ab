//! The runner's side of the recording: a [`Journal`] wraps the campaign's
//! [`Recorder`](recording::Recorder) (and, in a simulated run, the simulator's debug view,
//! a [`SimulatorView`]) so that the drive, the reset and the telemetry can record through a
//! shared reference.
//!
//! Recording never interrupts a drive: the first recording error is kept (later writes are
//! skipped) and the runner ends the campaign with [`RunError::Recording`] at the end of the
//! test, after the car's safe stop. The journal's methods therefore return nothing.

use std::future::Future;
use std::sync::{Mutex, MutexGuard};

use super::RunError;
use crate::vehicle::SimulatorView;
use campaign::files::CampaignRecord;
use car_link::{CarError, StateSample};
use recording::{CarCommand, Held, Record, Recorder, RecordingError};

/// The recorder and the first error it returned.
#[derive(Debug)]
struct State {
    recorder: Option<Recorder>,
    error: Option<RecordingError>,
}

/// The campaign's recording, shared by the runner's parts (see the module doc).
pub struct Journal<'a> {
    state: Mutex<State>,
    sim: Option<&'a dyn SimulatorView>,
}

impl std::fmt::Debug for Journal<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Journal")
            .field("state", &self.state)
            .field("simulated", &self.sim.is_some())
            .finish()
    }
}

impl<'a> Journal<'a> {
    /// Records through `recorder`; with `sim`, every state sample also records the simulator's
    /// truth and debug events.
    pub fn new(recorder: Recorder, sim: Option<&'a dyn SimulatorView>) -> Self {
        Self {
            state: Mutex::new(State {
                recorder: Some(recorder),
                error: None,
            }),
            sim,
        }
    }

    /// Records nothing (a run whose recording is not wanted, e.g. a shrink's candidates); the
    /// simulator's debug events are still drained.
    pub fn without_recording(sim: Option<&'a dyn SimulatorView>) -> Self {
        Self {
            state: Mutex::new(State {
                recorder: None,
                error: None,
            }),
            sim,
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `write` on the recorder unless an error happened before; keeps its error.
    fn with<T>(&self, write: impl FnOnce(&mut Recorder) -> Result<T, RecordingError>) -> Option<T> {
        let mut state = self.lock();
        if state.error.is_some() {
            return None;
        }
        let result = write(state.recorder.as_mut()?);
        match result {
            Ok(value) => Some(value),
            Err(error) => {
                state.error = Some(error);
                None
            }
        }
    }

    /// Records `message` on its channel now.
    pub fn write<R: Record>(&self, message: &R) {
        self.with(|r| r.write(message));
    }

    /// Records a command about to be sent; its id for [`Journal::answered`] (`None` once
    /// recording failed).
    pub fn sent(&self, test_index: Option<usize>, command: CarCommand) -> Option<u64> {
        self.with(|r| r.command_sent(test_index, command))
    }

    /// Records the answer to command `id`.
    pub fn answered<T, E: std::fmt::Display>(&self, id: Option<u64>, result: &Result<T, E>) {
        if let Some(id) = id {
            self.with(|r| r.command_answered(id, result));
        }
    }

    /// Sends a command with `send`, recording it and its answer.
    pub async fn call<T, Fut>(
        &self,
        test_index: Option<usize>,
        command: CarCommand,
        send: Fut,
    ) -> Result<T, CarError>
    where
        Fut: Future<Output = Result<T, CarError>>,
    {
        let id = self.sent(test_index, command);
        let result = send.await;
        self.answered(id, &result);
        result
    }

    /// Records a state sample and, in a simulated run, the simulator's truth and the debug
    /// events since the last sample.
    pub fn state(&self, sample: &StateSample) {
        self.with(|r| r.car_state(sample));
        if let Some(sim) = self.sim {
            let truth = sim.truth();
            let events = sim.take_events();
            self.with(|r| {
                r.sim_truth(&truth)?;
                r.sim_events(&events)
            });
        }
    }

    /// From now on, holds what is recorded until [`Journal::release`] (`run --record failing`).
    pub fn hold(&self) {
        self.with(|r| {
            r.hold();
            Ok(())
        });
    }

    /// Writes what was held when `keep`, drops it otherwise.
    pub fn release(&self, keep: bool) {
        self.with(|r| r.release(keep));
    }

    /// Takes what a journal in memory holds (see [`Recorder::in_memory`]).
    pub fn take_held(&self) -> Vec<Held> {
        self.with(Recorder::take_held).unwrap_or_default()
    }

    /// Drops what a journal in memory holds, unencoded (a test `run --record failing` does not
    /// keep).
    pub fn drop_held(&self) {
        self.with(|r| {
            r.drop_held();
            Ok(())
        });
    }

    /// Writes messages another journal held, log time shifted by `offset_ns`.
    pub fn write_held(&self, held: Vec<Held>, offset_ns: u64) {
        self.with(|r| r.write_held(held, offset_ns));
    }

    /// Records the span of log time of test `test_index`'s messages.
    pub fn test_span(&self, test_index: usize, start_ns: u64, end_ns: u64, car: Option<&str>) {
        self.with(|r| r.test_span(test_index, start_ns, end_ns, car));
    }

    /// Writes the open chunk to the file (end of a test).
    pub fn flush(&self) {
        self.with(Recorder::flush);
    }

    /// The first recording error, as the campaign's error.
    pub fn check(&self) -> Result<(), RunError> {
        match self.lock().error.take() {
            Some(error) => Err(RunError::Recording(error)),
            None => Ok(()),
        }
    }

    /// Writes the campaign's end record and completes the file.
    pub fn finish(self, campaign: &CampaignRecord) -> Result<(), RunError> {
        let state = self.state.into_inner().unwrap_or_else(|e| e.into_inner());
        if let Some(error) = state.error {
            return Err(RunError::Recording(error));
        }
        let Some(mut recorder) = state.recorder else {
            return Ok(());
        };
        recorder
            .campaign_ended(campaign)
            .and_then(|()| recorder.finish())
            .map(drop)
            .map_err(RunError::Recording)
    }
}
