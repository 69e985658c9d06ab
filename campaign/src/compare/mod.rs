//! Comparing two runs of the same tests (`drivecheck compare BASE NEW`): is NEW better or worse
//! than BASE, and where? The method is `docs/compare.md`'s; this module is pure.
//!
//! 1. **Rows.** Each case becomes a small [`TestRow`] ([`TestRow::of`]): its verdict, a digest of
//!    every command as driven, and a [`SegmentRow`] per segment driven (verdict, largest
//!    deviation, the active faults' probe and kind, the commanded speed, the route). The caller
//!    reads a case, keeps its row and drops the case, so memory grows with rows, not cases.
//! 2. **Pairing** ([`pair`]): the two runs must hold the same tests (same test indices, same
//!    scenario, the same commands as driven: points with their speeds, faults with their values
//!    and places; not the generator's intent or the never-driven ahead margin), else a
//!    [`PairError`] names the first difference. A test's segments driven in both runs are paired;
//!    those driven in only one (a test stopped at a failing segment) are counted, not paired.
//! 3. **Statistics** ([`compare`]): McNemar's exact test on the tests whose verdict differs
//!    (regressed `b`: BASE passed, NEW did not; fixed `c`: the other way), and the median change
//!    of a paired segment's largest deviation (NEW − BASE) with its 95 % interval from a cluster
//!    bootstrap over tests and its p from a sign-flip randomization test over tests. NEW is
//!    significantly worse when McNemar's two-sided p < α/2 with `b > c`, or the sign-flip p <
//!    α/2 with a median change above 0 (Bonferroni over the two tests: the chance of a false
//!    alarm stays at most α); better likewise; [`Significance::Mixed`] when one test says worse
//!    and the other better.
//! 4. **Breakdowns** ([`Breakdowns`]): by active fault (probe and kind), by commanded speed band
//!    and by region of the area, the row that explains most of the regression first.

mod breakdown;
mod stats;

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;
use thiserror::Error;

use crate::files::{Case, CommandRecord};
use crate::model::{Command, FaultKind, Probe};
use crate::oracle::{SegmentVerdict, Verdict};

pub use breakdown::{BreakdownRow, Breakdowns};
pub use stats::{
    Bootstrap, SignFlip, bootstrap_median, mcnemar_p, median, nearest_rank, sign_flip_median,
};

/// The significance level when none is given.
pub const DEFAULT_ALPHA: f64 = 0.05;
/// The bootstrap's resamples when none are given.
pub const DEFAULT_RESAMPLES: usize = 2000;
/// The bootstrap's seed when none is given (`campaign::seed::rng` of it).
pub const DEFAULT_BOOTSTRAP_SEED: u64 = 0;
/// The width of a speed band of the breakdown, km/h (the coverage's speed bins are as wide).
pub const DEFAULT_SPEED_BAND_KMH: f64 = 2.0;
/// The side of a region's square cell of the breakdown, metres.
pub const DEFAULT_REGION_CELL_M: f64 = 10.0;
/// The level of the interval shown beside the median change (the decision's is 1 − α/2).
pub const SHOWN_LEVEL: f64 = 0.95;

/// One of the two runs compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Run {
    /// The run compared against.
    Base,
    /// The run judged.
    New,
}

impl fmt::Display for Run {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Run::Base => "BASE",
            Run::New => "NEW",
        })
    }
}

/// Why two runs cannot be compared: they do not hold the same tests. The first difference in
/// test order.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PairError {
    /// Neither run has a test.
    #[error("neither run has a test to compare")]
    NoTests,
    /// A test index appears twice in one run.
    #[error("{run} has test {test_index} twice")]
    Duplicate {
        /// The run.
        run: Run,
        /// The test.
        test_index: usize,
    },
    /// A test is in one run and not the other.
    #[error("test {test_index} is in {present} but not in {missing}")]
    Missing {
        /// The test.
        test_index: usize,
        /// The run that has it.
        present: Run,
        /// The run that does not.
        missing: Run,
    },
    /// A test ran in another scenario (name or content hash).
    #[error("test {test_index} ran in another scenario: BASE {base}, NEW {new}")]
    Scenario {
        /// The test.
        test_index: usize,
        /// BASE's scenario (name and hash).
        base: String,
        /// NEW's.
        new: String,
    },
    /// A test's commands differ; the first that does.
    #[error("test {test_index}, command {command_index} differs: BASE {base}, NEW {new}")]
    Command {
        /// The test.
        test_index: usize,
        /// The first command index that differs.
        command_index: usize,
        /// BASE's command there, in words (`none` past its last).
        base: String,
        /// NEW's.
        new: String,
    },
}

/// An option of [`compare`] that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OptionsError {
    /// α outside (0, 1).
    #[error("alpha {0}: must be between 0 and 1")]
    Alpha(f64),
    /// A noise that is not a length.
    #[error("noise {0}: must be a length in metres, 0 or more")]
    Noise(f64),
    /// No resample.
    #[error("the bootstrap needs at least one resample")]
    Resamples,
    /// A band or cell that is not a positive length.
    #[error("{what} {value}: must be positive")]
    Size {
        /// Which.
        what: &'static str,
        /// The value.
        value: f64,
    },
}

/// A fault's probe and kind: what a breakdown row of faults is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FaultKey {
    /// The probe.
    pub probe: Probe,
    /// The kind.
    pub kind: FaultKind,
}

impl fmt::Display for FaultKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.probe, self.kind.name())
    }
}

/// What a command is, in a few words, and a digest of it as driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandDigest {
    /// FNV-1a (64 bits) of the command as driven: a segment's points with their speeds; a
    /// fault's probe, kind, parameter, start, duration and place.
    pub digest: u64,
    /// What it is.
    pub what: CommandWhat,
}

/// What a command is, for an error's words.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CommandWhat {
    /// A `run_segments` of this many points.
    Segment {
        /// Its points.
        points: usize,
    },
    /// An `add_fault`.
    Fault(FaultKey),
}

impl fmt::Display for CommandWhat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Segment { points } => write!(f, "run_segments of {points} points"),
            Self::Fault(key) => write!(f, "add_fault {key}"),
        }
    }
}

impl CommandDigest {
    /// The digest of `record` as driven: [`CommandRecord::to_command`] (the command replay
    /// sends), without the generator's intent and the ahead margin, which are never driven.
    pub fn of(record: &CommandRecord) -> Self {
        let mut h = Fnv::new();
        match record.to_command() {
            Command::RunSegments(segment) => {
                h.byte(1);
                h.u64(segment.points.len() as u64);
                for (p, v) in segment.points.iter().zip(&segment.speeds) {
                    h.f64(p.x);
                    h.f64(p.y);
                    h.f64(*v);
                }
                Self {
                    digest: h.0,
                    what: CommandWhat::Segment {
                        points: segment.points.len(),
                    },
                }
            }
            Command::AddFault(fault) => {
                h.byte(2);
                h.bytes(fault.probe.to_string().as_bytes());
                h.byte(0);
                h.bytes(fault.kind.name().as_bytes());
                h.f64(fault.param);
                h.u64(u64::from(fault.start));
                h.u64(u64::from(fault.duration));
                match fault.at {
                    None => h.byte(0),
                    Some(at) => {
                        h.byte(1);
                        h.u64(at.segment_index as u64);
                        h.f64(at.along_m);
                    }
                }
                Self {
                    digest: h.0,
                    what: CommandWhat::Fault(FaultKey {
                        probe: fault.probe,
                        kind: fault.kind,
                    }),
                }
            }
        }
    }
}

/// FNV-1a, 64 bits: a digest that is the same in every process and on every machine.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    fn byte(&mut self, b: u8) {
        self.0 ^= u64::from(b);
        self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
    }
    fn bytes(&mut self, bytes: &[u8]) {
        bytes.iter().for_each(|&b| self.byte(b));
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
}

/// One segment a run drove, as the comparison needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentRow {
    /// Its index among the test's segments.
    pub segment_index: usize,
    /// The oracle's verdict.
    pub verdict: SegmentVerdict,
    /// Its largest deviation |UWB − RTK|, metres (`None` without a judged sample).
    pub max_m: Option<f64>,
    /// The probe and kind of every fault estimated to be acting while it was driven, sorted,
    /// each once.
    pub faults: Vec<FaultKey>,
    /// The commanded speed, m/s: the generator's `intent.speed_mps`, else the fastest of its
    /// points' speeds (a hand-written case).
    pub speed_mps: Option<f64>,
    /// Its route: the previous segment's last point (when there is one) and its points, `[x, y]`.
    pub route: Vec<[f64; 2]>,
}

/// One test of a run, as the comparison needs it (a few numbers per command and segment).
#[derive(Debug, Clone, PartialEq)]
pub struct TestRow {
    /// Its index in the campaign.
    pub test_index: usize,
    /// The scenario: its name and content hash (`-` when the case has none).
    pub scenario: String,
    /// Every command, digested.
    pub commands: Vec<CommandDigest>,
    /// Its verdict (`None`: not run).
    pub verdict: Option<Verdict>,
    /// Every segment driven.
    pub segments: Vec<SegmentRow>,
}

impl TestRow {
    /// The row of `case`, whose file says it is test `file_index` when the case does not.
    pub fn of(case: &Case, file_index: usize) -> Self {
        let mut routes: BTreeMap<usize, (Option<f64>, Vec<[f64; 2]>)> = BTreeMap::new();
        let mut last: Option<[f64; 2]> = None;
        for (i, command) in case.commands.iter().enumerate() {
            if let CommandRecord::RunSegments { intent, points, .. } = command {
                let speed = intent.map(|i| i.speed_mps).or_else(|| {
                    points
                        .iter()
                        .map(|p| p.speed)
                        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))
                });
                let route: Vec<[f64; 2]> = last
                    .into_iter()
                    .chain(points.iter().map(|p| [p.x, p.y]))
                    .collect();
                last = route.last().copied();
                routes.insert(i, (speed, route));
            }
        }
        let segments = case
            .segments
            .iter()
            .map(|s| {
                let mut faults: Vec<FaultKey> = s
                    .faults_active
                    .iter()
                    .filter_map(|&i| match case.commands.get(i) {
                        Some(CommandRecord::AddFault { probe, kind, .. }) => Some(FaultKey {
                            probe: *probe,
                            kind: *kind,
                        }),
                        _ => None,
                    })
                    .collect();
                faults.sort();
                faults.dedup();
                let (speed_mps, route) = routes.get(&s.command_index).cloned().unwrap_or_default();
                SegmentRow {
                    segment_index: s.segment_index,
                    verdict: s.oracle.verdict,
                    max_m: s.oracle.stats.map(|st| st.max_m).filter(|m| m.is_finite()),
                    faults,
                    speed_mps,
                    route,
                }
            })
            .collect();
        Self {
            test_index: case.test_index.unwrap_or(file_index),
            scenario: format!(
                "{} ({})",
                case.scenario.name,
                case.scenario.hash.as_deref().unwrap_or("-")
            ),
            commands: case.commands.iter().map(CommandDigest::of).collect(),
            verdict: case.verdict,
            segments,
        }
    }
}

/// A segment driven in both runs.
#[derive(Debug, Clone, PartialEq)]
pub struct PairedSegment {
    /// The test.
    pub test_index: usize,
    /// Its index among the test's segments.
    pub segment_index: usize,
    /// BASE's verdict of it.
    pub base_verdict: SegmentVerdict,
    /// NEW's.
    pub new_verdict: SegmentVerdict,
    /// BASE's largest deviation, metres.
    pub base_max_m: Option<f64>,
    /// NEW's.
    pub new_max_m: Option<f64>,
    /// The faults acting in either run (sorted, each once); empty: none.
    pub faults: Vec<FaultKey>,
    /// The commanded speed, m/s.
    pub speed_mps: Option<f64>,
    /// Its route, `[x, y]`.
    pub route: Vec<[f64; 2]>,
}

impl PairedSegment {
    /// NEW's largest deviation minus BASE's, metres, when both have one.
    pub fn change_m(&self) -> Option<f64> {
        Some(self.new_max_m? - self.base_max_m?)
    }

    /// BASE passed it, NEW did not.
    pub fn regressed(&self) -> bool {
        self.base_verdict == SegmentVerdict::Passed && self.new_verdict != SegmentVerdict::Passed
    }

    /// BASE did not pass it, NEW did.
    pub fn fixed(&self) -> bool {
        self.base_verdict != SegmentVerdict::Passed && self.new_verdict == SegmentVerdict::Passed
    }

    /// The middle of its route by length (its only point, or `None` without one).
    pub fn midpoint(&self) -> Option<[f64; 2]> {
        let route = &self.route;
        let first = *route.first()?;
        let length: f64 = route.windows(2).map(|w| dist(w[0], w[1])).sum();
        let mut left = length / 2.0;
        for w in route.windows(2) {
            let d = dist(w[0], w[1]);
            if d >= left && d > 0.0 {
                let t = left / d;
                return Some([
                    w[0][0] + t * (w[1][0] - w[0][0]),
                    w[0][1] + t * (w[1][1] - w[0][1]),
                ]);
            }
            left -= d;
        }
        Some(first)
    }

    fn swapped(&self) -> Self {
        Self {
            base_verdict: self.new_verdict,
            new_verdict: self.base_verdict,
            base_max_m: self.new_max_m,
            new_max_m: self.base_max_m,
            ..self.clone()
        }
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// A test in both runs.
#[derive(Debug, Clone, PartialEq)]
pub struct PairedTest {
    /// The test.
    pub test_index: usize,
    /// BASE's verdict.
    pub base_verdict: Option<Verdict>,
    /// NEW's.
    pub new_verdict: Option<Verdict>,
    /// Its segments driven in both runs, in order.
    pub segments: Vec<PairedSegment>,
    /// Its segments driven only in BASE.
    pub only_base: usize,
    /// Only in NEW.
    pub only_new: usize,
}

/// How a test's verdict changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TestChange {
    /// Passed in both.
    BothPassed,
    /// Failed (or aborted, or not run) in both.
    BothFailed,
    /// BASE failed or aborted, NEW passed.
    Fixed,
    /// BASE passed, NEW failed or aborted.
    Regressed,
}

impl PairedTest {
    /// How its verdict changed (only `passed` is a pass: `aborted` and not run are not).
    pub fn change(&self) -> TestChange {
        let passed = |v: Option<Verdict>| v == Some(Verdict::Passed);
        match (passed(self.base_verdict), passed(self.new_verdict)) {
            (true, true) => TestChange::BothPassed,
            (false, false) => TestChange::BothFailed,
            (false, true) => TestChange::Fixed,
            (true, false) => TestChange::Regressed,
        }
    }
}

/// The two runs' tests, paired.
#[derive(Debug, Clone, PartialEq)]
pub struct Paired {
    /// Every test, by test index.
    pub tests: Vec<PairedTest>,
}

impl Paired {
    /// Every paired segment, in test and segment order.
    pub fn segments(&self) -> impl Iterator<Item = &PairedSegment> {
        self.tests.iter().flat_map(|t| &t.segments)
    }

    /// The same pairs with BASE and NEW exchanged.
    pub fn swapped(&self) -> Self {
        Self {
            tests: self
                .tests
                .iter()
                .map(|t| PairedTest {
                    test_index: t.test_index,
                    base_verdict: t.new_verdict,
                    new_verdict: t.base_verdict,
                    segments: t.segments.iter().map(PairedSegment::swapped).collect(),
                    only_base: t.only_new,
                    only_new: t.only_base,
                })
                .collect(),
        }
    }

    /// The noise of a rerun: when NEW is BASE's tests driven again on the same car (another
    /// seed), the 95th percentile (nearest rank) of |change| of the segments' largest deviation.
    /// `None` without a paired segment with both deviations.
    pub fn rerun_noise_m(&self) -> Option<f64> {
        let mut changes: Vec<f64> = self
            .segments()
            .filter_map(PairedSegment::change_m)
            .map(f64::abs)
            .collect();
        changes.sort_by(f64::total_cmp);
        nearest_rank(&changes, 0.95)
    }
}

fn by_index(rows: Vec<TestRow>, run: Run) -> Result<BTreeMap<usize, TestRow>, PairError> {
    let mut map = BTreeMap::new();
    for row in rows {
        let test_index = row.test_index;
        if map.insert(test_index, row).is_some() {
            return Err(PairError::Duplicate { run, test_index });
        }
    }
    Ok(map)
}

/// Pairs BASE's tests with NEW's (see the module doc): refused, naming the first difference in
/// test order, when they are not the same tests.
pub fn pair(base: Vec<TestRow>, new: Vec<TestRow>) -> Result<Paired, PairError> {
    let base = by_index(base, Run::Base)?;
    let mut new = by_index(new, Run::New)?;
    if base.is_empty() && new.is_empty() {
        return Err(PairError::NoTests);
    }
    let first_only_new = new.keys().find(|i| !base.contains_key(i)).copied();
    let mut tests = Vec::with_capacity(base.len());
    for (test_index, b) in base {
        if let Some(only_new) = first_only_new.filter(|&i| i < test_index) {
            return Err(PairError::Missing {
                test_index: only_new,
                present: Run::New,
                missing: Run::Base,
            });
        }
        let Some(n) = new.remove(&test_index) else {
            return Err(PairError::Missing {
                test_index,
                present: Run::Base,
                missing: Run::New,
            });
        };
        if b.scenario != n.scenario {
            return Err(PairError::Scenario {
                test_index,
                base: b.scenario,
                new: n.scenario,
            });
        }
        let count = b.commands.len().max(n.commands.len());
        if let Some(command_index) = (0..count)
            .find(|&i| b.commands.get(i).map(|c| c.digest) != n.commands.get(i).map(|c| c.digest))
        {
            let words = |c: Option<&CommandDigest>, other: Option<&CommandDigest>| match (c, other)
            {
                (None, _) => "none (it has no more commands)".to_owned(),
                (Some(c), Some(o)) if c.what == o.what => format!("{} (other values)", c.what),
                (Some(c), _) => c.what.to_string(),
            };
            return Err(PairError::Command {
                test_index,
                command_index,
                base: words(b.commands.get(command_index), n.commands.get(command_index)),
                new: words(n.commands.get(command_index), b.commands.get(command_index)),
            });
        }
        tests.push(pair_test(b, n));
    }
    if let Some(test_index) = first_only_new {
        return Err(PairError::Missing {
            test_index,
            present: Run::New,
            missing: Run::Base,
        });
    }
    Ok(Paired { tests })
}

fn pair_test(b: TestRow, n: TestRow) -> PairedTest {
    let mut new_segments: BTreeMap<usize, SegmentRow> = n
        .segments
        .into_iter()
        .map(|s| (s.segment_index, s))
        .collect();
    let mut segments = Vec::new();
    let mut only_base = 0;
    for s in b.segments {
        match new_segments.remove(&s.segment_index) {
            None => only_base += 1,
            Some(t) => {
                let mut faults = s.faults;
                faults.extend(t.faults);
                faults.sort();
                faults.dedup();
                segments.push(PairedSegment {
                    test_index: b.test_index,
                    segment_index: s.segment_index,
                    base_verdict: s.verdict,
                    new_verdict: t.verdict,
                    base_max_m: s.max_m,
                    new_max_m: t.max_m,
                    faults,
                    speed_mps: s.speed_mps,
                    route: s.route,
                });
            }
        }
    }
    PairedTest {
        test_index: b.test_index,
        base_verdict: b.verdict,
        new_verdict: n.verdict,
        segments,
        only_base,
        only_new: new_segments.len(),
    }
}

/// What a comparison is asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// The significance level α (the chance of a false alarm, at most).
    pub alpha: f64,
    /// The noise, metres: a segment's largest deviation changed by more than this got worse (or
    /// better) by more than the noise.
    pub noise_m: f64,
    /// The bootstrap's resamples.
    pub resamples: usize,
    /// The bootstrap's seed.
    pub seed: u64,
    /// The width of a speed band, km/h.
    pub speed_band_kmh: f64,
    /// The side of a region's cell, metres.
    pub region_cell_m: f64,
}

impl Options {
    /// The defaults with the noise `noise_m`.
    pub fn with_noise(noise_m: f64) -> Self {
        Self {
            alpha: DEFAULT_ALPHA,
            noise_m,
            resamples: DEFAULT_RESAMPLES,
            seed: DEFAULT_BOOTSTRAP_SEED,
            speed_band_kmh: DEFAULT_SPEED_BAND_KMH,
            region_cell_m: DEFAULT_REGION_CELL_M,
        }
    }

    fn check(&self) -> Result<(), OptionsError> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(OptionsError::Alpha(self.alpha));
        }
        if !(self.noise_m.is_finite() && self.noise_m >= 0.0) {
            return Err(OptionsError::Noise(self.noise_m));
        }
        if self.resamples == 0 {
            return Err(OptionsError::Resamples);
        }
        for (what, value) in [
            ("speed band", self.speed_band_kmh),
            ("region cell", self.region_cell_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(OptionsError::Size { what, value });
            }
        }
        Ok(())
    }
}

/// The tests by how their verdict changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct TestCounts {
    /// Tests in both runs.
    pub paired: usize,
    /// Passed in both.
    pub both_passed: usize,
    /// Failed (or aborted) in both.
    pub both_failed: usize,
    /// BASE failed or aborted, NEW passed.
    pub fixed: usize,
    /// BASE passed, NEW failed or aborted.
    pub regressed: usize,
}

/// The segments.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SegmentCounts {
    /// Segments driven in both runs.
    pub paired: usize,
    /// Of those, with a largest deviation in both (a change).
    pub measured: usize,
    /// Driven only in BASE (NEW's test stopped earlier).
    pub only_base: usize,
    /// Driven only in NEW.
    pub only_new: usize,
    /// Changed by more than the noise upwards: worse.
    pub worse: usize,
    /// Changed by more than the noise downwards: better.
    pub better: usize,
    /// `worse / measured` (0 without a measured segment).
    pub worse_share: f64,
    /// `better / measured`.
    pub better_share: f64,
    /// BASE passed it, NEW did not.
    pub regressed: usize,
    /// BASE did not pass it, NEW did.
    pub fixed: usize,
}

/// McNemar's exact test on the tests' verdicts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct McNemar {
    /// Regressed tests (`b`).
    pub regressed: usize,
    /// Fixed tests (`c`).
    pub fixed: usize,
    /// Two-sided p.
    pub p: f64,
}

/// The median change of a paired segment's largest deviation: its bootstrap interval and its
/// sign-flip p.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MedianChange {
    /// The median of NEW − BASE over the measured segments, metres.
    pub median_m: f64,
    /// The 95 % interval, metres.
    pub ci95_m: [f64; 2],
    /// The sign-flip randomization test's two-sided p (the decision's).
    pub p: f64,
    /// Sign assignments of the randomization test (all `2^tests` when that is at most
    /// `resamples`: then `p` is exact).
    pub flips: usize,
    /// Bootstrap resamples drawn.
    pub resamples: usize,
    /// The seed of the bootstrap and of the sign flips.
    pub seed: u64,
    /// Tests resampled (those with a measured segment).
    pub tests: usize,
}

/// What the two tests say together.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Significance {
    /// NEW is significantly worse (and not significantly better by the other test).
    Worse,
    /// NEW is significantly better (and not significantly worse).
    Better,
    /// One test says worse, the other better.
    Mixed,
    /// Neither test is significant.
    NoDifference,
}

/// Which test found what, at its Bonferroni-corrected level (α/2 each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Evidence {
    /// McNemar's p < α/2 with more regressed than fixed tests.
    pub verdicts_worse: bool,
    /// McNemar's p < α/2 with more fixed than regressed tests.
    pub verdicts_better: bool,
    /// The sign-flip p of the median change < α/2 with a median above 0.
    pub deviation_worse: bool,
    /// The same with a median below 0.
    pub deviation_better: bool,
}

/// The comparison of two runs (`drivecheck compare`'s JSON, the `comparison` field).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The significance level α.
    pub alpha: f64,
    /// The noise, metres.
    pub noise_m: f64,
    /// The tests by verdict change.
    pub tests: TestCounts,
    /// The segments.
    pub segments: SegmentCounts,
    /// McNemar's test.
    pub mcnemar: McNemar,
    /// The median change (`None` without a measured segment).
    pub median_change: Option<MedianChange>,
    /// What each test found.
    pub evidence: Evidence,
    /// The conclusion.
    pub significance: Significance,
    /// The conclusion in words.
    pub verdict: String,
    /// Where the difference lives.
    pub breakdowns: Breakdowns,
}

/// Compares the paired runs (see the module doc): a typed error only for unusable options.
pub fn compare(paired: &Paired, options: &Options) -> Result<Report, OptionsError> {
    options.check()?;
    let mut tests = TestCounts {
        paired: paired.tests.len(),
        both_passed: 0,
        both_failed: 0,
        fixed: 0,
        regressed: 0,
    };
    for t in &paired.tests {
        match t.change() {
            TestChange::BothPassed => tests.both_passed += 1,
            TestChange::BothFailed => tests.both_failed += 1,
            TestChange::Fixed => tests.fixed += 1,
            TestChange::Regressed => tests.regressed += 1,
        }
    }
    let noise = options.noise_m;
    let mut segments = SegmentCounts {
        paired: 0,
        measured: 0,
        only_base: paired.tests.iter().map(|t| t.only_base).sum(),
        only_new: paired.tests.iter().map(|t| t.only_new).sum(),
        worse: 0,
        better: 0,
        worse_share: 0.0,
        better_share: 0.0,
        regressed: 0,
        fixed: 0,
    };
    let mut clusters: Vec<Vec<f64>> = Vec::with_capacity(paired.tests.len());
    for t in &paired.tests {
        let mut changes = Vec::with_capacity(t.segments.len());
        for s in &t.segments {
            segments.paired += 1;
            segments.regressed += usize::from(s.regressed());
            segments.fixed += usize::from(s.fixed());
            if let Some(change) = s.change_m() {
                segments.measured += 1;
                segments.worse += usize::from(change > noise);
                segments.better += usize::from(change < -noise);
                changes.push(change);
            }
        }
        clusters.push(changes);
    }
    if segments.measured > 0 {
        segments.worse_share = segments.worse as f64 / segments.measured as f64;
        segments.better_share = segments.better as f64 / segments.measured as f64;
    }
    let mcnemar = McNemar {
        regressed: tests.regressed,
        fixed: tests.fixed,
        p: mcnemar_p(tests.regressed as u64, tests.fixed as u64),
    };
    let flips = sign_flip_median(&clusters, options.resamples, options.seed);
    let median_change = bootstrap_median(&clusters, options.resamples, options.seed)
        .zip(flips)
        .map(|(boot, flips)| {
            let (lo, hi) = boot.interval(SHOWN_LEVEL);
            MedianChange {
                median_m: boot.median,
                ci95_m: [lo, hi],
                p: flips.p,
                flips: flips.flips,
                resamples: options.resamples,
                seed: options.seed,
                tests: boot.clusters,
            }
        });
    let half = options.alpha / 2.0;
    let evidence = Evidence {
        verdicts_worse: mcnemar.p < half && mcnemar.regressed > mcnemar.fixed,
        verdicts_better: mcnemar.p < half && mcnemar.fixed > mcnemar.regressed,
        deviation_worse: median_change.is_some_and(|m| m.p < half && m.median_m > 0.0),
        deviation_better: median_change.is_some_and(|m| m.p < half && m.median_m < 0.0),
    };
    let worse = evidence.verdicts_worse || evidence.deviation_worse;
    let better = evidence.verdicts_better || evidence.deviation_better;
    let significance = match (worse, better) {
        (true, true) => Significance::Mixed,
        (true, false) => Significance::Worse,
        (false, true) => Significance::Better,
        (false, false) => Significance::NoDifference,
    };
    let verdict = verdict_words(
        options.alpha,
        significance,
        &mcnemar,
        median_change.as_ref(),
    );
    let breakdowns = Breakdowns::of(paired, options);
    Ok(Report {
        alpha: options.alpha,
        noise_m: noise,
        tests,
        segments,
        mcnemar,
        median_change,
        evidence,
        significance,
        verdict,
        breakdowns,
    })
}

/// A p-value in words: three decimals, or two significant digits below 0.001.
pub fn p_words(p: f64) -> String {
    if p >= 0.001 {
        format!("{p:.3}")
    } else {
        format!("{p:.1e}")
    }
}

fn verdict_words(
    alpha: f64,
    significance: Significance,
    mcnemar: &McNemar,
    median: Option<&MedianChange>,
) -> String {
    let conclusion = match significance {
        Significance::Worse => format!("NEW is significantly worse at {alpha}"),
        Significance::Better => format!("NEW is significantly better at {alpha}"),
        Significance::Mixed => {
            format!("NEW is significantly worse by one measure and better by the other at {alpha}")
        }
        Significance::NoDifference => format!("no significant difference at {alpha}"),
    };
    let tests = format!(
        "NEW fails {} {} that BASE passed and fixes {} (McNemar p = {})",
        mcnemar.regressed,
        if mcnemar.regressed == 1 {
            "test"
        } else {
            "tests"
        },
        mcnemar.fixed,
        p_words(mcnemar.p)
    );
    let deviation = match median {
        None => "no segment was measured in both runs".to_owned(),
        Some(m) => {
            let how = if m.median_m > 0.0 {
                format!("grew by {:.3} m", m.median_m)
            } else if m.median_m < 0.0 {
                format!("shrank by {:.3} m", -m.median_m)
            } else {
                "did not change".to_owned()
            };
            format!(
                "a segment's largest deviation {how} (median; 95 % CI {:+.3} to {:+.3} m; \
                 sign-flip p = {})",
                m.ci95_m[0],
                m.ci95_m[1],
                p_words(m.p)
            )
        }
    };
    format!("{conclusion}: {tests}; {deviation}")
}

#[cfg(test)]
mod tests;
