//! The command generators: proptest strategies for the next command, given the reference state.
//!
//! The choice between commands follows the scenario's weights, restricted to the commands whose
//! preconditions can hold in the state (a fault command is offered only while its probe has a
//! free slot; anchor faults only when the scenario has anchors). A `RunSegments` strategy draws
//! an intent (seed, points, speed) and generates its concrete points with `trajgen` from the
//! state's tail; an intent whose generation fails is rejected (a local reject of proptest's
//! runner) and the failure is kept for the error report.

use std::sync::{Arc, Mutex};

use car_link::firmware::Param;
use proptest::prelude::*;
use proptest::sample::select;
use proptest::strategy::Union;
use scenarios::{CampaignSettings, Interval, ProbeFaults};
use trajgen::{GenerationError, Generator, RouteTail};

use super::command::{Command, Fault, FaultKind, FaultPlace, Probe, Segment, SegmentIntent};
use super::state::{Preconditions, ReferenceState};

/// Kilometres per hour in one metre per second.
const KMH_PER_MPS: f64 = 3.6;

/// Everything the strategies need, shared by every closure of one plan.
#[derive(Debug)]
pub(crate) struct PlanContext {
    pub(crate) preconditions: Preconditions,
    pub(crate) generator: Generator,
    pub(crate) settings: CampaignSettings,
    /// The last generation failure seen, reported when a plan cannot be completed.
    pub(crate) last_failure: Mutex<Option<GenerationError>>,
}

impl PlanContext {
    /// The segment an intent gives from `tail`: `trajgen` seeded with the intent's seed.
    pub(crate) fn generate(
        &self,
        tail: &RouteTail,
        intent: SegmentIntent,
    ) -> Result<Segment, GenerationError> {
        let mut rng = crate::seed::rng(intent.seed);
        let area = &self.preconditions.area;
        let extension = self.generator.extend(area, tail, intent.points, &mut rng)?;
        Ok(Segment::generated_from(
            tail,
            intent,
            extension.points,
            extension.margin,
        ))
    }

    fn remember(&self, error: GenerationError) {
        if let Ok(mut last) = self.last_failure.lock() {
            *last = Some(error);
        }
    }

    /// The generation failure seen last, if any.
    pub(crate) fn take_failure(&self) -> Option<GenerationError> {
        self.last_failure
            .lock()
            .ok()
            .and_then(|mut last| last.take())
    }
}

/// The strategy for the next command in `state`.
pub(crate) fn next_command(
    ctx: &Arc<PlanContext>,
    state: &ReferenceState,
) -> BoxedStrategy<Command> {
    let weights = ctx.settings.weights;
    if state.segments == 0 {
        // Every test first drives a segment (see `Preconditions::fault_fits`).
        return segment(ctx, state.tail);
    }
    let mut options = vec![(weights.run_segments, segment(ctx, state.tail))];
    if let Some(strategy) = anchor_fault(ctx, state) {
        options.push((weights.anchor_range_fault, placed(strategy, state)));
    }
    if state.slots.check(Probe::UwbTravelDist).is_ok() {
        let strategy = wheel_slip_fault(&ctx.settings);
        options.push((weights.wheel_slip_fault, placed(strategy, state)));
    }
    if state.slots.check(Probe::UwbYaw).is_ok() {
        options.push((weights.yaw_fault, placed(yaw_fault(&ctx.settings), state)));
    }
    options.retain(|(weight, _)| *weight > 0);
    Union::new_weighted(options).boxed()
}

fn segment(ctx: &Arc<PlanContext>, tail: RouteTail) -> BoxedStrategy<Command> {
    let settings = &ctx.settings;
    let points = settings.points_per_segment;
    let speed = settings.speed_kmh;
    let ctx = Arc::clone(ctx);
    (any::<u64>(), points.min..=points.max, speed.min..=speed.max)
        .prop_filter_map("no drivable extension", move |(seed, points, kmh)| {
            let intent = SegmentIntent {
                seed,
                points,
                speed_mps: kmh / KMH_PER_MPS,
            };
            ctx.generate(&tail, intent)
                .map_err(|error| ctx.remember(error))
                .ok()
                .map(Command::RunSegments)
        })
        .boxed()
}

/// A fault command placed on the segment just planned: anywhere along it, drawn as the share of
/// the segment left before its end, so that a place shrinks towards the segment's end (where the
/// earlier tool sent faults). Written to the millimetre.
fn placed(fault: BoxedStrategy<Command>, state: &ReferenceState) -> BoxedStrategy<Command> {
    let segment_index = state.segments.saturating_sub(1);
    let length = state.last_segment_m;
    (fault, 0.0..=1.0f64)
        .prop_map(move |(mut command, left)| {
            if let Command::AddFault(fault) = &mut command {
                let along_m = (length * (1.0 - left) * 1000.0).round() / 1000.0;
                fault.at = Some(FaultPlace {
                    segment_index,
                    along_m: along_m.min((length * 1000.0).floor() / 1000.0),
                });
            }
            command
        })
        .boxed()
}

fn anchor_fault(ctx: &PlanContext, state: &ReferenceState) -> Option<BoxedStrategy<Command>> {
    let settings = &ctx.settings.faults.anchor_range;
    let probes: Vec<Probe> = ctx
        .preconditions
        .anchors
        .iter()
        .map(|&anchor| Probe::UwbRange(u16::from(anchor)))
        .filter(|&probe| state.slots.check(probe).is_ok())
        .collect();
    if probes.is_empty() || settings.kinds.is_empty() {
        return None;
    }
    let strategy = (
        select(probes),
        kind_and_param(settings),
        range_u32(settings.start),
        range_u32(settings.duration),
    )
        .prop_map(|(probe, kind_param, start, duration)| {
            fault_command(probe, kind_param, start, duration)
        });
    Some(strategy.boxed())
}

fn wheel_slip_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    probe_fault(Probe::UwbTravelDist, &settings.faults.wheel_slip)
}

fn yaw_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    probe_fault(Probe::UwbYaw, &settings.faults.yaw)
}

/// The parameter of a `kind` fault: a value of its range; for a bitflip, a bit's number (the
/// scenario's validation keeps those whole).
fn param(faults: &ProbeFaults, kind: FaultKind) -> BoxedStrategy<f64> {
    let range = faults.range(kind);
    match kind.spec().param {
        Param::Value | Param::Factor => range_f64(range).boxed(),
        Param::Bit => (range.min as u32..=range.max as u32)
            .prop_map(f64::from)
            .boxed(),
        Param::Unused => Just(0.0).boxed(),
    }
}

/// A kind among the section's kinds (the scenario's validation keeps the list non-empty) and its
/// parameter. A probe with one kind draws no kind, and kinds that share one parameter range (an
/// anchor's offset and amplification) draw the kind and the parameter independently, so the
/// method's default tests are drawn exactly as before the other kinds existed.
///
/// A neutral draw (an offset of exactly 0, an amplification of exactly 1: a fault that does
/// nothing) is drawn again; the scenario's validation refuses a range that holds nothing else.
fn kind_and_param(faults: &ProbeFaults) -> BoxedStrategy<(FaultKind, f64)> {
    kind_and_any_param(faults)
        .prop_filter("a neutral parameter does nothing", |&(kind, param)| {
            kind.spec().neutral != Some(param)
        })
        .boxed()
}

fn kind_and_any_param(faults: &ProbeFaults) -> BoxedStrategy<(FaultKind, f64)> {
    let kinds = &faults.kinds;
    let continuous = |kind: FaultKind| matches!(kind.spec().param, Param::Value | Param::Factor);
    match kinds.as_slice() {
        [kind] => {
            let kind = *kind;
            param(faults, kind)
                .prop_map(move |param| (kind, param))
                .boxed()
        }
        [first, ..]
            if kinds
                .iter()
                .all(|&k| continuous(k) && faults.range(k) == faults.range(*first)) =>
        {
            (select(kinds.clone()), range_f64(faults.range(*first))).boxed()
        }
        _ => {
            let faults = faults.clone();
            select(kinds.clone())
                .prop_flat_map(move |kind| param(&faults, kind).prop_map(move |p| (kind, p)))
                .boxed()
        }
    }
}

fn probe_fault(probe: Probe, faults: &ProbeFaults) -> BoxedStrategy<Command> {
    (
        kind_and_param(faults),
        range_u32(faults.start),
        range_u32(faults.duration),
    )
        .prop_map(move |(kind_param, start, duration)| {
            fault_command(probe, kind_param, start, duration)
        })
        .boxed()
}

/// The fault command drawn (its place is drawn by [`placed`]).
fn fault_command(
    probe: Probe,
    (kind, param): (FaultKind, f64),
    start: u32,
    duration: u32,
) -> Command {
    Command::AddFault(Fault {
        probe,
        kind,
        param,
        start,
        duration,
        at: None,
    })
}

fn range_f64(interval: Interval<f64>) -> std::ops::RangeInclusive<f64> {
    interval.min..=interval.max
}

fn range_u32(interval: Interval<u32>) -> std::ops::RangeInclusive<u32> {
    interval.min..=interval.max
}
