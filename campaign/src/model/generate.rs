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
use rand::SeedableRng;
use scenarios::{CampaignSettings, Interval};
use trajgen::{GenerationError, Generator, RouteTail};

use super::command::{Command, Fault, FaultKind, Probe, Segment, SegmentIntent, range_fault_kind};
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
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(intent.seed);
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
        options.push((weights.anchor_range_fault, strategy));
    }
    if state.slots.check(Probe::UwbTravelDist).is_ok() {
        options.push((weights.wheel_slip_fault, wheel_slip_fault(&ctx.settings)));
    }
    if state.slots.check(Probe::UwbYaw).is_ok() {
        options.push((weights.yaw_fault, yaw_fault(&ctx.settings)));
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

fn anchor_fault(ctx: &PlanContext, state: &ReferenceState) -> Option<BoxedStrategy<Command>> {
    let settings = &ctx.settings.faults.anchor_range;
    let probes: Vec<Probe> = ctx
        .preconditions
        .anchors
        .iter()
        .map(|&anchor| Probe::UwbRange(u16::from(anchor)))
        .filter(|&probe| state.slots.check(probe).is_ok())
        .collect();
    let kinds: Vec<FaultKind> = settings
        .kinds
        .iter()
        .map(|&k| range_fault_kind(k))
        .collect();
    if probes.is_empty() || kinds.is_empty() {
        return None;
    }
    let strategy = (
        select(probes),
        select(kinds),
        range_f64(settings.param),
        range_u32(settings.start),
        range_u32(settings.duration),
    )
        .prop_map(|(probe, kind, param, start, duration)| {
            Command::AddFault(Fault {
                probe,
                kind,
                param,
                start,
                duration,
            })
        });
    Some(strategy.boxed())
}

fn wheel_slip_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    let slip = settings.faults.wheel_slip;
    simple_fault(
        Probe::UwbTravelDist,
        FaultKind::Amplification,
        slip.amplification,
        slip.start,
        slip.duration,
    )
}

fn yaw_fault(settings: &CampaignSettings) -> BoxedStrategy<Command> {
    let yaw = settings.faults.yaw;
    simple_fault(
        Probe::UwbYaw,
        FaultKind::Offset,
        yaw.offset_deg,
        yaw.start,
        yaw.duration,
    )
}

fn simple_fault(
    probe: Probe,
    kind: FaultKind,
    param: Interval<f64>,
    start: Interval<u32>,
    duration: Interval<u32>,
) -> BoxedStrategy<Command> {
    (range_f64(param), range_u32(start), range_u32(duration))
        .prop_map(move |(param, start, duration)| {
            Command::AddFault(Fault {
                probe,
                kind,
                param,
                start,
                duration,
            })
        })
        .boxed()
}

fn range_f64(interval: Interval<f64>) -> std::ops::RangeInclusive<f64> {
    interval.min..=interval.max
}

fn range_u32(interval: Interval<u32>) -> std::ops::RangeInclusive<u32> {
    interval.min..=interval.max
}
