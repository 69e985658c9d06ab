//! The abstract model of the car and the test generator (`docs/method.md#the-model`), on
//! `proptest`.
//!
//! A test is a sequence of [`Command`]s generated against a [`ReferenceState`]: the route tail
//! the next segment must extend, the faults in flight and the firmware's fault slots. Commands are
//! `RunSegments` (a [`Segment`]: a generated extension of the route with its intent, its concrete
//! points and its ahead margin) and `AddFault` (a [`Fault`] on a [`Probe`]). Their weights and
//! parameter ranges come from the scenario's `CampaignSettings`; preconditions ([`Preconditions`])
//! keep every test drivable (each segment plus its margin passes `trajgen::check_route`
//! continuing the tail) and inside the firmware's 5 × 5 fault slots. The postcondition of
//! `RunSegments` is the oracle (`crate::oracle`), evaluated by the runner while the car drives.
//!
//! # How proptest is used, and how a seed maps to a test
//!
//! Generation is separate from execution: a test is planned completely before the car drives
//! it, because a car cannot be asked to re-run a prefix. The plan is built with
//! `proptest-state-machine`'s `Sequential` strategy (the generation of its `ReferenceStateMachine`
//! half only, copied into `model::sequential`, which says why), but constructed with `Sequential::new` and closures
//! rather than through the trait: the trait's `init_state()` and `transitions()` take no arguments, and the scenario,
//! the start tail and the settings would have to come from global state. Its
//! `StateMachineTest` half (which executes while it generates) is not used: executing is the
//! runner's job, in real time, with streaming and a safety monitor.
//!
//! One campaign seed determines everything:
//! 1. test `i` of campaign seed `s` gets a 32-byte seed from SplitMix64 over `(s, i)`
//!    ([`crate::seed::plan_seed`], the seed map), which seeds proptest's ChaCha `TestRng` and a
//!    `TestRunner`;
//! 2. the test's size grows linearly over the campaign ([`test_size`]);
//! 3. the `Sequential` strategy draws each command from the weighted union of the commands
//!    allowed in the current state; a `RunSegments` draws an intent `(seed, points, speed)` and its
//!    points come from `trajgen::Generator::extend` seeded with `crate::seed::rng(seed)`
//!    from the current tail (scenario generator settings, [`trajgen::Strategy::Wedge`]);
//! 4. with `no_faults` the test is generated exactly the same way and its `AddFault` commands are
//!    then removed, so a campaign with and without faults drives the same routes (what "the same
//!    campaign passes with `--no-faults`" compares).
//!
//! Plans are deterministic for a given tool version; a case file records the concrete commands,
//! so replay never depends on regenerating them.
//!
//! # Shrinking
//!
//! Not here, and never through proptest: [`TestPlanner::plan_test`] takes the strategy's first
//! value. A failing case is shrunk by `crate::shrink`, which edits the recorded case and drives
//! each candidate on the simulated car (`docs/method.md#replay-and-shrinking`).

mod command;
mod generate;
mod sequential;
mod state;
mod timing;

use std::sync::{Arc, Mutex};

use proptest::strategy::{BoxedStrategy, Just, Strategy as _};
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use scenarios::{CampaignSettings, FaultTarget, Interval, Scenario};
use thiserror::Error;
use trajgen::{GenerationError, Generator, RouteTail, Strategy};

pub use command::{
    Command, Fault, FaultKind, FaultPlace, Probe, Segment, SegmentIntent, UnknownProbe,
};
pub use state::{FaultInFlight, FaultSlots, Preconditions, ReferenceState, SlotError};
pub use timing::{FaultWindow, ProbeRates};

use generate::PlanContext;
use sequential::Sequential;

/// Local rejects (intents whose generation failed) allowed while planning one test.
const MAX_REJECTS: u32 = 16;

/// What determines a campaign's tests besides the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Campaign {
    /// The one seed every random choice derives from.
    pub seed: u64,
    /// Number of tests in the campaign (test sizes grow over it).
    pub tests: usize,
    /// Plan the tests without their fault commands.
    pub no_faults: bool,
}

/// Why no plan could be made.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ModelError {
    /// The scenario's campaign settings cannot generate tests.
    #[error("invalid campaign settings: {0}")]
    InvalidSettings(String),
    /// The scenario's generator settings are invalid.
    #[error("invalid generator settings: {0}")]
    Generator(#[source] GenerationError),
    /// The route tail the test starts from cannot be continued.
    #[error("the test cannot start from this route tail: {0}")]
    StartTail(#[source] GenerationError),
    /// No drivable extension was found for the segments of a test.
    #[error("test {test_index}: no drivable segment could be generated: {source}")]
    Generation {
        /// The test.
        test_index: usize,
        /// The last generation failure.
        source: GenerationError,
    },
    /// proptest gave up for another reason.
    #[error("test {test_index}: planning failed: {reason}")]
    Planning {
        /// The test.
        test_index: usize,
        /// proptest's reason.
        reason: String,
    },
}

/// A planned test: the concrete command sequence the runner executes.
#[derive(Debug, Clone, PartialEq)]
pub struct TestPlan {
    /// The test's index in its campaign (from 0).
    pub test_index: usize,
    /// The route tail the test starts from (the end of the start route).
    pub start_tail: RouteTail,
    /// The commands, in order.
    pub commands: Vec<Command>,
}

impl TestPlan {
    /// The `RunSegments` commands with their command indices.
    pub fn segments(&self) -> impl Iterator<Item = (usize, &Segment)> {
        self.commands
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.segment().map(|s| (i, s)))
    }

    /// The `AddFault` commands with their command indices.
    pub fn faults(&self) -> impl Iterator<Item = (usize, &Fault)> {
        self.commands
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.fault().map(|f| (i, f)))
    }

    /// Indices of the fault commands before command `command_index` (the faults that preceded
    /// it; slots are never freed within a test, so all of them may still be pending or active).
    pub fn faults_before(&self, command_index: usize) -> Vec<usize> {
        self.faults()
            .map(|(i, _)| i)
            .take_while(|&i| i < command_index)
            .collect()
    }

    /// The route tail after the last segment (where the safe stop continues from).
    pub fn end_tail(&self) -> RouteTail {
        self.segments()
            .fold(self.start_tail, |tail, (_, s)| tail.advanced(&s.points))
    }
}

/// The number of commands of test `test_index` of `tests`: linear from `size.min` for the first
/// test to `size.max` for the last, rounded to the nearest integer (a single test gets
/// `size.min`; indices past the end get `size.max`). Default 5–20 over 10 tests:
/// 5, 7, 8, 10, 12, 13, 15, 17, 18, 20.
pub fn test_size(size: Interval<usize>, test_index: usize, tests: usize) -> usize {
    let span = size.max.saturating_sub(size.min);
    let Some(last) = tests.checked_sub(1).filter(|&last| last > 0) else {
        return size.min;
    };
    let index = test_index.min(last);
    // Integer rounding of span * index / last, in u128 so no setting can overflow it.
    let (span, index, last) = (span as u128, index as u128, last as u128);
    let step = (2 * span * index + last) / (2 * last);
    size.min + usize::try_from(step).unwrap_or(usize::MAX - size.min)
}

/// The route tail after a scenario's start route: where every test starts.
pub fn start_tail(scenario: &Scenario) -> Result<RouteTail, ModelError> {
    RouteTail::from_points(&scenario.start_route.positions()).map_err(ModelError::StartTail)
}

/// Plans test `test_index` of `campaign` in `scenario`, starting from `start_tail`.
/// Deterministic: the same arguments give the same plan.
pub fn plan_test(
    scenario: &Scenario,
    campaign: &Campaign,
    test_index: usize,
    start_tail: RouteTail,
) -> Result<TestPlan, ModelError> {
    TestPlanner::new(scenario)?.plan_test(campaign, test_index, start_tail)
}

/// Plans the tests of one scenario (validates its settings once).
#[derive(Debug, Clone)]
pub struct TestPlanner {
    preconditions: Preconditions,
    generator: Generator,
    settings: CampaignSettings,
}

type PlanStrategy =
    Sequential<ReferenceState, Command, BoxedStrategy<ReferenceState>, BoxedStrategy<Command>>;
impl TestPlanner {
    /// A planner for `scenario`, with its generator (wedge strategy) and campaign settings.
    pub fn new(scenario: &Scenario) -> Result<Self, ModelError> {
        check_settings(&scenario.campaign)?;
        let config = scenario.generator.generator_config(Strategy::Wedge);
        let generator = Generator::new(config).map_err(ModelError::Generator)?;
        Ok(Self {
            preconditions: Preconditions {
                area: scenario.area.clone(),
                constraints: scenario.constraints(),
                ahead_margin: config.ahead_margin,
                anchors: scenario.anchors.iter().map(|a| a.id).collect(),
            },
            generator,
            settings: scenario.campaign.clone(),
        })
    }

    /// The generator (the scenario's, wedge strategy).
    pub fn generator(&self) -> &Generator {
        &self.generator
    }

    /// The preconditions commands are planned under.
    pub fn preconditions(&self) -> &Preconditions {
        &self.preconditions
    }

    /// Plans test `test_index` of `campaign` from `start_tail` (see the module doc).
    pub fn plan_test(
        &self,
        campaign: &Campaign,
        test_index: usize,
        start_tail: RouteTail,
    ) -> Result<TestPlan, ModelError> {
        if !self.preconditions.area.contains_point(start_tail.end) {
            return Err(ModelError::StartTail(GenerationError::TailOutside {
                at: start_tail.end,
            }));
        }
        let ctx = Arc::new(PlanContext {
            preconditions: self.preconditions.clone(),
            generator: self.generator,
            settings: self.settings.clone(),
            last_failure: Mutex::new(None),
        });
        let size = test_size(self.settings.test_size, test_index, campaign.tests);
        let strategy = sequential(&ctx, start_tail, size);
        let mut runner = runner(campaign.seed, test_index);
        let (_, commands) =
            strategy
                .generate(&mut runner)
                .map_err(|reason| match ctx.take_failure() {
                    Some(source) => ModelError::Generation { test_index, source },
                    None => ModelError::Planning {
                        test_index,
                        reason: reason.to_string(),
                    },
                })?;
        let commands = commands
            .into_iter()
            .filter(|c| !(campaign.no_faults && c.fault().is_some()))
            .collect();
        Ok(TestPlan {
            test_index,
            start_tail,
            commands,
        })
    }
}

fn sequential(ctx: &Arc<PlanContext>, start_tail: RouteTail, size: usize) -> PlanStrategy {
    let pre = Arc::clone(ctx);
    let next = Arc::clone(ctx);
    Sequential::new(
        (size..=size).into(),
        move || Just(ReferenceState::new(start_tail)).boxed(),
        move |state, command| pre.preconditions.allow(state, command),
        move |state| generate::next_command(&next, state),
        |state, command| state.apply(command),
    )
}

fn runner(campaign_seed: u64, test_index: usize) -> TestRunner {
    let config = Config {
        max_local_rejects: MAX_REJECTS,
        failure_persistence: None,
        ..Config::default()
    };
    let rng = TestRng::from_seed(
        RngAlgorithm::ChaCha,
        &crate::seed::plan_seed(campaign_seed, test_index),
    );
    TestRunner::new_with_rng(config, rng)
}

/// Checks what the strategies would otherwise panic on: empty or inverted ranges, zero weights.
fn check_settings(s: &CampaignSettings) -> Result<(), ModelError> {
    let f = &s.faults;
    let problems = [
        (s.test_size.min == 0, "test_size.min must be at least 1"),
        (s.test_size.min > s.test_size.max, "test_size: min > max"),
        (
            s.points_per_segment.min == 0,
            "points_per_segment.min must be at least 1",
        ),
        (
            inverted(s.points_per_segment),
            "points_per_segment: min > max",
        ),
        (
            bad_f64(s.speed_kmh) || s.speed_kmh.min <= 0.0,
            "speed_kmh must be a positive range",
        ),
        (
            s.weights.run_segments == 0,
            "weights.run_segments must be positive",
        ),
        (
            weight_sum(s) > u64::from(u32::MAX),
            "the weights' sum overflows",
        ),
    ];
    if let Some((_, reason)) = problems.iter().find(|(bad, _)| *bad) {
        return Err(ModelError::InvalidSettings((*reason).to_owned()));
    }
    for target in FaultTarget::ALL {
        let faults = f.get(target);
        let section = target.section();
        if let Some(kind) = faults
            .kinds
            .iter()
            .find(|&&kind| bad_f64(faults.range(kind)))
        {
            return Err(ModelError::InvalidSettings(format!(
                "faults.{section}: bad {} range",
                kind.name()
            )));
        }
        if bad_u32(faults.start) || bad_duration(faults.duration) {
            return Err(ModelError::InvalidSettings(format!(
                "faults.{section}: bad start or duration"
            )));
        }
    }
    Ok(())
}

fn inverted<T: PartialOrd>(i: Interval<T>) -> bool {
    i.min > i.max
}

fn bad_f64(i: Interval<f64>) -> bool {
    !(i.min.is_finite() && i.max.is_finite()) || inverted(i)
}

fn bad_u32(i: Interval<u32>) -> bool {
    inverted(i)
}

/// A duration of 0 means "permanent" to the firmware: generated faults never use it.
fn bad_duration(i: Interval<u32>) -> bool {
    i.min == 0 || inverted(i)
}

fn weight_sum(s: &CampaignSettings) -> u64 {
    let w = s.weights;
    [
        w.run_segments,
        w.anchor_range_fault,
        w.wheel_slip_fault,
        w.yaw_fault,
    ]
    .into_iter()
    .map(u64::from)
    .sum()
}

#[cfg(test)]
mod tests;
