//! The command generators: proptest strategies for the next command, given the reference state.
//!
//! The choice between commands follows the scenario's weights, restricted to the commands whose
//! preconditions can hold in the state (a fault command is offered only while its probe has a
//! free slot; anchor faults only when the scenario has anchors). A `RunSegments` strategy draws
//! an intent (seed, points, speed) and generates its concrete points with `trajgen` from the
//! state's tail; an intent whose generation fails is rejected (a local reject of proptest's
//! runner) and the failure is kept for the error report.

use std::sync::{Arc, Mutex};

use proptest::prelude::*;
use proptest::sample::select;
use proptest::strategy::Union;
use scenarios::{CampaignSettings, Interval};
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
    let ranges = KindRanges {
        offset: settings.param,
        amplification: settings.param,
        set_to: settings.set_to_m,
        bitflip_bits: settings.bitflip_bits,
    };
    let strategy = (
        select(probes),
        kind_and_param(&settings.kinds, ranges),
        range_u32(settings.start),
        range_u32(settings.duration),
    )
        .prop_map(|(probe, kind_param, start, duration)| {
            fault_command(probe, kind_param, start, duration)
        });
    Some(strategy.boxed())
}

fn wheel_slip_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    let slip = &settings.faults.wheel_slip;
    let ranges = KindRanges {
        offset: slip.offset_m,
        amplification: slip.amplification,
        set_to: slip.set_to_m,
        bitflip_bits: slip.bitflip_bits,
    };
    probe_fault(
        Probe::UwbTravelDist,
        kind_and_param(&slip.kinds, ranges),
        slip.start,
        slip.duration,
    )
}

fn yaw_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    let yaw = &settings.faults.yaw;
    let ranges = KindRanges {
        offset: yaw.offset_deg,
        amplification: yaw.amplification,
        set_to: yaw.set_to_deg,
        bitflip_bits: yaw.bitflip_bits,
    };
    probe_fault(
        Probe::UwbYaw,
        kind_and_param(&yaw.kinds, ranges),
        yaw.start,
        yaw.duration,
    )
}

/// The parameter range of each fault kind on one probe.
#[derive(Debug, Clone, Copy)]
struct KindRanges {
    offset: Interval<f64>,
    amplification: Interval<f64>,
    set_to: Interval<f64>,
    bitflip_bits: Interval<u32>,
}

impl KindRanges {
    /// The parameter of a `kind` fault: a value of its range; for a bitflip, the bit's number.
    fn param(self, kind: FaultKind) -> BoxedStrategy<f64> {
        match kind {
            FaultKind::Offset => range_f64(self.offset).boxed(),
            FaultKind::Amplification => range_f64(self.amplification).boxed(),
            FaultKind::SetTo => range_f64(self.set_to).boxed(),
            FaultKind::Bitflip => range_u32(self.bitflip_bits).prop_map(f64::from).boxed(),
            FaultKind::None => Just(0.0).boxed(),
        }
    }
}

/// A kind among `kinds` (the scenario's validation keeps the list non-empty) and its parameter.
/// A probe with one kind draws no kind, and kinds that share one parameter range (an anchor's
/// offset and amplification) draw the kind and the parameter independently, so the method's
/// default tests are drawn exactly as before the other kinds existed.
fn kind_and_param(kinds: &[FaultKind], ranges: KindRanges) -> BoxedStrategy<(FaultKind, f64)> {
    let shared = |range: Interval<f64>| {
        kinds.iter().all(|&kind| match kind {
            FaultKind::Offset => ranges.offset == range,
            FaultKind::Amplification => ranges.amplification == range,
            FaultKind::SetTo => ranges.set_to == range,
            FaultKind::Bitflip | FaultKind::None => false,
        })
    };
    match kinds {
        [kind] => {
            let kind = *kind;
            ranges
                .param(kind)
                .prop_map(move |param| (kind, param))
                .boxed()
        }
        _ if shared(ranges.offset) => (select(kinds.to_vec()), range_f64(ranges.offset)).boxed(),
        _ => select(kinds.to_vec())
            .prop_flat_map(move |kind| ranges.param(kind).prop_map(move |param| (kind, param)))
            .boxed(),
    }
}

fn probe_fault(
    probe: Probe,
    kind_and_param: BoxedStrategy<(FaultKind, f64)>,
    start: Interval<u32>,
    duration: Interval<u32>,
) -> BoxedStrategy<Command> {
    (kind_and_param, range_u32(start), range_u32(duration))
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
