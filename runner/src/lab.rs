//! A campaign on several cars at once (`drivecheck run --car A=tcp://… --car B=tcp://…`): a lab
//! of HIL boards, or cars on separate tracks. Each car is the whole method on its own: its
//! preflight, its telemetry, and per test its reset, drive, safety monitor and safe stop; the
//! tests are dealt to whichever car is free, in test order.
//!
//! A car that fails (its link lost, preflight refused, a command or its reset failed) leaves the
//! campaign and the others go on: the test it was cut off in keeps its case as
//! `case-NNN.partial-K.json` (as `run --resume` keeps a test cut off) and goes back to the front of
//! the queue, so every test still ends once. When the last car fails, the campaign ends as an
//! error as on one car (resumable with `run --resume`). An operator's interrupt stops every car
//! safely.
//!
//! Every car records into memory; when a test ends, its messages (with what its car recorded
//! since its previous test: preflight, telemetry between tests) are written into
//! `campaign.mcap` one test after the other, log time shifted to start 1 ms after the last
//! message before them, with a `drivecheck.test.<k>` span, as a campaign with `--jobs` lays its
//! tests end to end: the cars drive at once, but no reader of the recording sees two cars on one
//! channel. The live view gets every car's messages as they happen, on topics of its own
//! (`/<car>/car/state`, …; `recording::live::LiveView::for_car`).
//!
//! Not here: the test itself (`super::plan_and_run`), the car's session (`super::open_session`).

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;

use scenarios::Scenario;
use tokio_util::sync::CancellationToken;
use trajgen::Point;

use super::journal::Journal;
use super::run_dir::RunDirectory;
use super::{
    CampaignFailure, CampaignObserver, CampaignReport, RecordMode, RunConfig, RunError,
    SPAN_GAP_NS, TestEnd, TestSource, finish_campaign, open_session, plan_and_run, record_test_end,
    reset, start_join_note, switched_off_note,
};
use crate::vehicle::Vehicle;
use campaign::files::{CarRun, Case, Settings};
use campaign::oracle::Verdict;
use recording::{Held, Recorder};

/// One car of a campaign on several cars.
#[derive(Debug)]
pub struct LabCar<V> {
    /// What the progress, the case files and `campaign.json` call it.
    pub name: String,
    /// Its address as the user gave it.
    pub address: String,
    /// The car.
    pub car: V,
}

/// The first command id of car `k`'s recording: ids stay unique in the campaign's file, apart
/// from a fresh car's (`(test + 1) << 32`), and below 2⁵³ (exact in a JSON number).
fn first_command(k: usize) -> u64 {
    (1 << 52) | ((k as u64) << 40)
}

/// How often a car with no test left looks again while others drive (one of them may fail and
/// give its test back).
const IDLE_POLL: std::time::Duration = std::time::Duration::from_millis(200);

/// Does `error` say that the car it happened on cannot go on (as opposed to the campaign)?
fn is_car_failure(error: &RunError) -> bool {
    matches!(
        error,
        RunError::LinkLost { .. }
            | RunError::Unresponsive { .. }
            | RunError::Car { .. }
            | RunError::Preflight(_)
            | RunError::Reset { .. }
    )
}

/// What the cars share: the campaign's inputs, the queue of tests, the run directory.
struct Lab<'a> {
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cancel: &'a CancellationToken,
    observer: &'a dyn CampaignObserver,
    journal: &'a Journal<'a>,
    tests: TestSource<'a>,
    start_join: Vec<Point>,
    /// The settings of `campaign.json` as created (without the runtime constants).
    settings: Settings,
    origin: tokio::time::Instant,
    /// The tests not yet dealt, in order (a test cut off on a car that left goes to the front).
    queue: RefCell<VecDeque<usize>>,
    /// Cars still in the campaign (preparing, driving or waiting).
    cars_in: Cell<usize>,
    /// Cars driving a test now.
    busy: Cell<usize>,
    /// No car takes another test (an interrupt, a campaign error).
    stop: Cell<bool>,
    /// The first error that ends the campaign.
    error: RefCell<Option<RunError>>,
    /// Why each car that left did (name, reason), in the order they left.
    left: RefCell<Vec<(String, String)>>,
    state: RefCell<Written<'a>>,
}

/// What the cars write into: the run directory and where the next test's messages go.
struct Written<'a> {
    dir: &'a mut RunDirectory,
    /// Where the next test's messages start in the campaign's recording, ns.
    offset_ns: u64,
    /// A car passed preflight: the campaign's firmware and runtime constants are set.
    runtime_set: bool,
}

/// Runs a campaign on `cars` at once (see the module doc) and writes its run directory as
/// [`super::run_campaign`] does, with `campaign.json` listing the cars (`cars`: each car's tests
/// and why it left) and every case naming its car.
///
/// Returns the report when every test ran on some car; a [`CampaignFailure`] (with the report)
/// when the campaign could not end: interrupted, every car gone, a plan or a file that failed.
///
/// Timeout: as [`super::run_campaign`], per car. Cancellation: `cancel` makes every car's test
/// stop safely (recorded `aborted (interrupted)`); the campaign ends with
/// [`RunError::Interrupted`].
pub async fn run_campaign_on_cars<V: Vehicle>(
    cars: &[LabCar<V>],
    scenario: &Scenario,
    config: &RunConfig,
    cancel: &CancellationToken,
    observer: &dyn CampaignObserver,
) -> Result<CampaignReport, CampaignFailure> {
    let origin = tokio::time::Instant::now();
    let settings = Settings::new(scenario, config.campaign.tests, config.policy);
    let mut dir = RunDirectory::create(config, scenario, settings.clone())
        .map_err(CampaignFailure::without_report)?;
    dir.add_cars(cars.iter().map(|c| CarRun {
        name: c.name.clone(),
        address: c.address.clone(),
        firmware: None,
        tests: Vec::new(),
        session: None,
        left: None,
    }));
    let (journal, offset_ns) =
        match super::spanned_journal(config, scenario, &dir, origin, false, observer) {
            Ok(opened) => opened,
            Err(error) => return Err(super::recording_not_started(dir, error)),
        };
    let result = match prepare(scenario, config) {
        Ok((tests, start_join)) => {
            let indices = config.test_indices();
            observer.tests_planned(indices.len());
            let lab = Lab {
                scenario,
                config,
                cancel,
                observer,
                journal: &journal,
                tests,
                start_join,
                settings,
                origin,
                queue: RefCell::new(indices.into()),
                cars_in: Cell::new(cars.len()),
                busy: Cell::new(0),
                stop: Cell::new(false),
                error: RefCell::new(None),
                left: RefCell::new(Vec::new()),
                state: RefCell::new(Written {
                    dir: &mut dir,
                    offset_ns,
                    runtime_set: false,
                }),
            };
            futures::future::join_all(
                cars.iter()
                    .enumerate()
                    .map(|(k, car)| drive_car(&lab, k, car)),
            )
            .await;
            lab.outcome()
        }
        Err(error) => Err(error),
    };
    // Every car's session ends disarmed, a car that left too (best effort: its link may be
    // lost); after the second signal the command line does it.
    if !super::hard_stop().is_cancelled() {
        futures::future::join_all(
            cars.iter()
                .map(|car| super::end_session(&car.car, Some(&car.name), observer)),
        )
        .await;
    }
    finish_campaign(dir, journal, result)
}

/// The campaign's test source and the reset's planned join, made once for every car.
fn prepare<'a>(
    scenario: &'a Scenario,
    config: &'a RunConfig,
) -> Result<(TestSource<'a>, Vec<Point>), RunError> {
    Ok((
        TestSource::new(scenario, config)?,
        reset::plan_start_join(scenario, config.campaign.seed)?,
    ))
}

/// Car `k`'s part of the campaign: its session, then tests from the queue until it is empty,
/// the campaign stops or the car fails.
async fn drive_car<V: Vehicle>(lab: &Lab<'_>, k: usize, car: &LabCar<V>) {
    let config = lab.config;
    let live = config.live.as_ref().map(|l| l.for_car(&car.name));
    let journal = match (config.record, live.as_ref()) {
        (RecordMode::None, Some(live)) => {
            match Recorder::live_only(lab.origin, false, first_command(k), live, None) {
                Ok(recorder) => Journal::new(recorder, None),
                Err(error) => return lab.fail(RunError::Recording(error)),
            }
        }
        (RecordMode::None, None) => Journal::without_recording(None),
        (RecordMode::All | RecordMode::Failing, live) => Journal::new(
            Recorder::in_memory(lab.origin, false, first_command(k), live),
            None,
        ),
    };
    let session = open_session(
        &car.car,
        lab.scenario,
        config,
        lab.cancel,
        &journal,
        lab.start_join.clone(),
    )
    .await;
    let (ctx, mut telemetry, preflight) = match session {
        Ok(session) => session,
        Err(error @ RunError::Preflight(_)) => return lab.leave(&car.name, &error.to_string()),
        Err(error) => return lab.leave(&car.name, &format!("preflight: {error}")),
    };
    lab.ready(car, &preflight.switched_off, &ctx);
    let settings = lab
        .settings
        .clone()
        .with_runtime(ctx.safety, config.streaming);
    while !lab.stop.get() && !lab.cancel.is_cancelled() {
        let Some(test_index) = lab.queue.borrow_mut().pop_front() else {
            // A car still driving may yet fail and give its test back: wait for the others.
            if lab.busy.get() == 0 {
                break;
            }
            tokio::time::sleep(IDLE_POLL).await;
            continue;
        };
        lab.observer.test_started_on(test_index, &car.name);
        lab.busy.set(lab.busy.get() + 1);
        let ran = plan_and_run(&ctx, &mut telemetry, &lab.tests, test_index, &settings).await;
        lab.busy.set(lab.busy.get() - 1);
        let (mut case, end) = match ran {
            Ok(ran) => ran,
            Err(error) => return lab.fail(error),
        };
        case.car = Some(car.name.clone());
        record_test_end(&journal, test_index, &case);
        let end = match (end, journal.check()) {
            (TestEnd::Continue, Err(error)) => TestEnd::Stop(error),
            (end, _) => end,
        };
        // A car that stops answering sensibly leaves, its test cut off, while another car can
        // drive it (the last car's test is an aborted one, as on one car).
        let end = match (end, case.abort) {
            (TestEnd::Continue, Some(abort))
                if abort.reason.car_unresponsive() && lab.cars_in.get() > 1 =>
            {
                TestEnd::Stop(RunError::Unresponsive {
                    test_index,
                    reason: abort.reason,
                })
            }
            (end, _) => end,
        };
        match end {
            TestEnd::Stop(error) if is_car_failure(&error) && lab.cars_in.get() > 1 => {
                journal.drop_held();
                lab.cut_off(test_index, &case, &car.name, &error);
                return;
            }
            end => {
                // The last car failed: the campaign ends with it, and the record says so.
                if let TestEnd::Stop(error) = &end
                    && is_car_failure(error)
                    && let Some(record) = lab.state.borrow_mut().dir.car_mut(&car.name)
                {
                    record.left = Some(error.to_string());
                }
                let held = match config.record {
                    RecordMode::Failing if case.verdict == Some(Verdict::Passed) => {
                        journal.drop_held();
                        Vec::new()
                    }
                    _ => journal.take_held(),
                };
                if let Err(error) = lab.write_test(&case, held, end) {
                    return lab.fail(error);
                }
            }
        }
    }
    lab.cars_in.set(lab.cars_in.get() - 1);
}

impl Lab<'_> {
    /// Car `car` passed preflight: notes and `campaign.json` say what it found.
    fn ready<V: Vehicle>(
        &self,
        car: &LabCar<V>,
        switched_off: &[String],
        ctx: &super::Context<'_, V>,
    ) {
        if !switched_off.is_empty() {
            self.observer.note(&format!(
                "car {}: {}",
                car.name,
                switched_off_note(switched_off)
            ));
        }
        let mut state = self.state.borrow_mut();
        if let Some(record) = state.dir.car_mut(&car.name) {
            record.firmware = Some(car.car.version().to_string());
        }
        if !std::mem::replace(&mut state.runtime_set, true) {
            if !ctx.start_join.is_empty() {
                self.observer.note(&start_join_note(&ctx.start_join));
            }
            state.dir.set_firmware(car.car.version().to_string());
            state.dir.set_runtime(ctx.safety, self.config.streaming);
        }
    }

    /// Writes a test's case file and its messages into the recording, and reports it; `end`
    /// that stops the campaign stops every car.
    fn write_test(&self, case: &Case, held: Vec<Held>, end: TestEnd) -> Result<(), RunError> {
        let test_index = case.test_index.unwrap_or_default();
        let mut state = self.state.borrow_mut();
        // The span first (written through to the file), then the case file: a test with a case
        // file has its span (as in `fresh::write_test`).
        if let (Some(first), Some(last)) = (
            held.iter().map(Held::log_time).min(),
            held.iter().map(Held::log_time).max(),
        ) {
            let offset = state.offset_ns;
            // Shifted so that the first message is at `offset` (wrapping: the shift may be back).
            self.journal.write_held(held, offset.wrapping_sub(first));
            self.journal.test_span(
                test_index,
                offset,
                offset + (last - first),
                case.car.as_deref(),
            );
            state.offset_ns = offset + (last - first) + SPAN_GAP_NS;
        }
        self.journal.check()?;
        state.dir.write_case(case)?;
        drop(state);
        self.observer.test_finished(test_index, case.verdict);
        if let TestEnd::Stop(error) = end {
            self.fail(error);
        }
        Ok(())
    }

    /// Car `car` failed with `error` in test `test_index`: its case is kept as a partial, the
    /// test goes back to the front of the queue, and the car leaves.
    fn cut_off(&self, test_index: usize, case: &Case, car: &str, error: &RunError) {
        let kept = self.state.borrow_mut().dir.write_partial(case);
        match kept {
            Ok(path) => self.observer.note(&format!(
                "test {test_index} was cut off on car {car}: its case is kept as {}; another car drives it again",
                path.file_name().unwrap_or_default().to_string_lossy()
            )),
            Err(error) => return self.fail(error),
        }
        self.queue.borrow_mut().push_front(test_index);
        self.leave(car, &error.to_string());
    }

    /// Car `car` leaves the campaign for `reason`.
    fn leave(&self, car: &str, reason: &str) {
        self.cars_in.set(self.cars_in.get() - 1);
        self.left
            .borrow_mut()
            .push((car.to_owned(), reason.to_owned()));
        let mut state = self.state.borrow_mut();
        if let Some(record) = state.dir.car_mut(car) {
            record.left = Some(reason.to_owned());
        }
        if let Err(error) = state.dir.write_now() {
            drop(state);
            return self.fail(error);
        }
        drop(state);
        self.observer.car_left(car, reason);
    }

    /// The campaign stops with `error` (the first one kept): no car takes another test.
    fn fail(&self, error: RunError) {
        self.stop.set(true);
        self.error.borrow_mut().get_or_insert(error);
    }

    /// How the campaign ended once every car is done.
    fn outcome(&self) -> Result<(), RunError> {
        if let Some(error) = self.error.borrow_mut().take() {
            return Err(error);
        }
        let next = self.queue.borrow().front().copied();
        match next {
            None => Ok(()),
            Some(test_index) if self.cancel.is_cancelled() => {
                Err(RunError::Interrupted { test_index })
            }
            Some(test_index) => Err(RunError::NoCarLeft {
                test_index,
                cars: self.left.borrow().clone(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Silent;
    use campaign::model::Campaign;
    use std::time::Duration;

    /// Car K stopped after a time: shut down, or frozen.
    type Stop = (usize, Duration, fn(&car_sim::SimHandle));

    /// A campaign of `tests` tests on `cars` embedded simulated cars (each behind the client, in
    /// process, as a car behind a link is), in virtual time; car `kill.0` is stopped by `kill.2`
    /// `kill.1` after the start. The run directory, its report or failure, and the virtual time
    /// taken.
    async fn lab_campaign(
        tests: usize,
        cars: usize,
        kill: Option<Stop>,
    ) -> (
        tempfile::TempDir,
        Result<CampaignReport, CampaignFailure>,
        Duration,
    ) {
        let scenario = scenarios::bundled::load("parking-lot-2anchors")
            .unwrap()
            .scenario;
        let dir = tempfile::tempdir().unwrap();
        let campaign = Campaign {
            seed: 5,
            tests,
            no_faults: false,
        };
        let config = RunConfig::new(campaign, dir.path().join("run"), "lab");
        let mut lab = Vec::new();
        let mut handles = Vec::new();
        for k in 0..cars {
            let sim = car_sim::SimConfig {
                seed: 100 + k as u64,
                ..car_sim::SimConfig::from_scenario(&scenario)
            };
            let (car, handle) = crate::vehicle::connect_sim(&sim).await.unwrap();
            lab.push(LabCar {
                name: format!("car{}", k + 1),
                address: format!("sim#{k}"),
                car,
            });
            handles.push(handle);
        }
        let started = tokio::time::Instant::now();
        let killer = async {
            if let Some((k, after, stop)) = kill {
                tokio::time::sleep(after).await;
                stop(&handles[k]);
            }
        };
        let cancel = CancellationToken::new();
        let (result, ()) = tokio::join!(
            run_campaign_on_cars(&lab, &scenario, &config, &cancel, &Silent),
            killer
        );
        (dir, result, started.elapsed())
    }

    fn record(dir: &tempfile::TempDir) -> campaign::files::CampaignRecord {
        let text = std::fs::read_to_string(dir.path().join("run/campaign.json")).unwrap();
        campaign::files::CampaignRecord::from_json(&text).unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn two_cars_drive_every_test_once_in_about_half_the_time_of_one() {
        let (_one_dir, one, one_took) = lab_campaign(6, 1, None).await;
        let (dir, two, two_took) = lab_campaign(6, 2, None).await;
        let (one, two) = (one.unwrap(), two.unwrap());
        assert_eq!(one.tests.len(), 6);
        assert_eq!(two.tests.len(), 6);
        let ratio = two_took.as_secs_f64() / one_took.as_secs_f64();
        assert!(
            (0.35..0.7).contains(&ratio),
            "two cars took {two_took:?}, one {one_took:?}"
        );
        let record = record(&dir);
        let mut driven: Vec<usize> = record.cars.iter().flat_map(|c| c.tests.clone()).collect();
        driven.sort_unstable();
        assert_eq!(driven, (0..6).collect::<Vec<_>>());
        assert!(
            record
                .cars
                .iter()
                .all(|c| c.left.is_none() && !c.tests.is_empty())
        );
        for test in &two.tests {
            let case = two.case(test).unwrap();
            let car = record
                .cars
                .iter()
                .find(|c| c.tests.contains(&test.test_index))
                .unwrap();
            assert_eq!(case.car.as_deref(), Some(car.name.as_str()));
        }
        // One recording, a span per test naming its car, no two spans overlapping.
        let path = dir.path().join("run/campaign.mcap");
        assert!(recording::Recording::read(&path).unwrap().is_complete());
        let spans = recording::Spans::open(&path).unwrap();
        let mut seen = Vec::new();
        for span in spans {
            let span = span.unwrap();
            let Some(test_index) = span.test_index else {
                continue;
            };
            let case = two.case(&two.tests[test_index]).unwrap();
            assert_eq!(span.car, case.car, "test {test_index}");
            assert!(!span.messages.is_empty());
            seen.push((span.start_ns, span.end_ns, test_index));
        }
        seen.sort_unstable();
        assert_eq!(seen.len(), 6);
        assert!(seen.windows(2).all(|w| w[0].1 < w[1].0), "{seen:?}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_car_lost_mid_test_leaves_and_the_other_drives_its_test_again() {
        let (dir, result, _) = lab_campaign(
            4,
            2,
            Some((1, Duration::from_secs(20), car_sim::SimHandle::shutdown)),
        )
        .await;
        let report = result.unwrap();
        assert_eq!(report.tests.len(), 4);
        assert!(report.tests.iter().all(|t| !t.cut_off));
        let record = record(&dir);
        let lost = &record.cars[1];
        assert_eq!(lost.name, "car2");
        assert!(lost.left.is_some(), "{record:?}");
        assert_eq!(record.cars[0].tests.len() + lost.tests.len(), 4);
        let partials: Vec<_> = std::fs::read_dir(dir.path().join("run"))
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".partial-"))
            .collect();
        assert_eq!(partials, ["case-001.partial-1.json"]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_car_that_freezes_mid_test_leaves_and_the_other_drives_its_test_again() {
        // Frozen: the connection stays, the car answers nothing (its state goes stale).
        let (dir, result, _) = lab_campaign(
            4,
            2,
            Some((1, Duration::from_secs(20), car_sim::SimHandle::freeze)),
        )
        .await;
        let report = result.unwrap();
        assert_eq!(report.tests.len(), 4);
        assert!(report.tests.iter().all(|t| !t.cut_off));
        let record = record(&dir);
        let frozen = &record.cars[1];
        let left = frozen.left.as_deref().unwrap_or_default();
        assert!(
            left.contains("stopped answering sensibly (no state for"),
            "{record:?}"
        );
        // It took no test after the one it froze in; the other car drove every test.
        assert!(frozen.tests.is_empty(), "{record:?}");
        assert_eq!(record.cars[0].tests.len(), 4);
        let partial: Case = Case::from_json(
            &std::fs::read_to_string(dir.path().join("run/case-001.partial-1.json")).unwrap(),
        )
        .unwrap();
        assert!(
            partial.abort.unwrap().reason.car_unresponsive(),
            "{partial:?}"
        );
        let case: Case = Case::from_json(
            &std::fs::read_to_string(dir.path().join("run/case-001.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(case.car.as_deref(), Some("car1"));
    }

    #[tokio::test(start_paused = true)]
    async fn a_car_that_fails_its_preflight_leaves_and_the_others_drive_every_test() {
        let (dir, result, _) = lab_campaign(
            3,
            2,
            Some((0, Duration::ZERO, car_sim::SimHandle::shutdown)),
        )
        .await;
        let report = result.unwrap();
        assert_eq!(report.tests.len(), 3);
        let record = record(&dir);
        assert!(
            record.cars[0]
                .left
                .as_deref()
                .unwrap()
                .contains("preflight"),
            "{record:?}"
        );
        assert_eq!(record.cars[0].firmware, None);
        assert_eq!(record.cars[1].tests, [0, 1, 2]);
    }

    #[tokio::test(start_paused = true)]
    async fn when_the_last_car_is_lost_the_campaign_ends_as_an_error_it_can_resume() {
        let (dir, result, _) = lab_campaign(
            3,
            1,
            Some((0, Duration::from_secs(20), car_sim::SimHandle::shutdown)),
        )
        .await;
        let failure = result.unwrap_err();
        assert!(
            matches!(failure.error, RunError::LinkLost { test_index: 0 }),
            "{}",
            failure.error
        );
        assert!(dir.path().join("run/case-000.json").exists());
        let record = record(&dir);
        assert_eq!(
            record.cars[0].left.as_deref(),
            Some("test 0: the link to the car was lost")
        );
    }

    #[test]
    fn command_ids_of_cars_meet_neither_each_other_nor_fresh_cars_and_stay_exact_in_json() {
        assert!(first_command(0) > (1_000_000u64 + 1) << 32);
        assert!(first_command(0) + (1 << 40) <= first_command(1));
        assert!(first_command(4095) + (1 << 40) <= 1 << 53);
    }
}
