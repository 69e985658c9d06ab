//! Unit tests of the drive's phases.
use trajgen::Polygon;

use super::*;
use crate::model::{FaultKind, FaultPlace, Probe};
use crate::oracle::Verdict;

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

/// A 40 m × 20 m rectangle.
fn area() -> Area {
    let fence = Polygon::new(vec![
        Point::new(0.0, 0.0),
        Point::new(40.0, 0.0),
        Point::new(40.0, 20.0),
        Point::new(0.0, 20.0),
    ])
    .unwrap();
    Area::new(fence, vec![]).unwrap()
}

/// Points every 2 m along y = 10 from `from` to `to` (inclusive).
fn along(from: f64, to: f64) -> Vec<Point> {
    let n = ((to - from) / 2.0).round() as usize;
    (0..=n)
        .map(|i| Point::new(from + 2.0 * i as f64, 10.0))
        .collect()
}

/// The start route: x = 2 … 10 at 1 m/s.
fn start() -> Vec<Waypoint> {
    along(2.0, 10.0)
        .into_iter()
        .map(|position| Waypoint {
            position,
            speed: 1.0,
        })
        .collect()
}

/// A hand-written segment of 4 points at 1 m/s from `from` on.
fn segment(from: f64) -> Command {
    let points = along(from, from + 6.0);
    Command::RunSegments(Segment {
        intent: None,
        speeds: vec![1.0; points.len()],
        points,
        margin: Vec::new(),
    })
}

fn fault(probe: Probe) -> Command {
    Command::AddFault(Fault {
        probe,
        kind: FaultKind::Offset,
        param: 2.0,
        start: 0,
        duration: 50,
        at: None,
    })
}

fn plan(commands: Vec<Command>) -> TestPlan {
    let positions: Vec<Point> = start().iter().map(|w| w.position).collect();
    TestPlan {
        test_index: 0,
        start_tail: RouteTail::from_points(&positions).unwrap(),
        commands,
    }
}

fn settings(area: &Area, policy: FailurePolicy) -> DriveSettings<'_> {
    DriveSettings {
        area,
        generator: Generator::default(),
        // The harness moves its car by metres between samples: a test of the drive, not of
        // the monitor's plausibility check.
        safety: SafetyConfig {
            max_plausible_speed_mps: f64::INFINITY,
            ..SafetyConfig::default()
        },
        streaming: StreamingConfig::default(),
        policy,
        oracle_threshold_m: 1.0,
        stop_points: 4,
        rates: ProbeRates::new(car_link::FirmwareVersion::V10_1, 2),
        campaign_seed: 7,
        steering: Some(Steering::of(&scenarios::Vehicle::default())),
    }
}

const LINK: LinkStatus = LinkStatus {
    rtt_p99: Some(Duration::from_millis(20)),
    lossy: false,
    request_timeout: Duration::from_secs(1),
};

/// A drive on the straight route, fed with samples every 50 ms (round trips of 20 ms, so
/// the lead time is 20 ms + 0 ms generation + 1 s margin).
struct Harness<'a> {
    drive: TestDrive<'a>,
    now: Duration,
    /// The UWB estimate's offset from RTK (north), metres.
    uwb_offset: f64,
}

impl<'a> Harness<'a> {
    fn new(area: &'a Area, plan: &'a TestPlan, policy: FailurePolicy) -> Self {
        let drive = TestDrive::new(settings(area, policy), plan, &start(), Duration::ZERO);
        Self {
            drive,
            now: Duration::ZERO,
            uwb_offset: 0.0,
        }
    }

    /// One sample 50 ms after the last, of the car at `at` driving at `speed`.
    fn sample_at(&mut self, at: Point, speed: f64) -> Vec<Action> {
        self.now += ms(50);
        let sample = Sample {
            rtk: at,
            uwb: Point::new(at.x, at.y + self.uwb_offset),
            speed,
            round_trip: ms(20),
            yaw_deg: 0.0,
            version: car_link::firmware::FirmwareVersion::V10_1,
            look_ahead_radius_m: f64::NAN,
        };
        self.drive.handle(self.now, Event::Sample(sample))
    }

    /// One sample of the car at `x` on y = 10, at 1 m/s.
    fn sample(&mut self, x: f64) -> Vec<Action> {
        self.sample_at(Point::new(x, 10.0), 1.0)
    }

    fn next(&mut self) -> Option<Operation> {
        self.drive.next_operation(self.now, LINK)
    }

    fn reply(&mut self, reply: Reply) -> Vec<Action> {
        self.drive.handle(self.now, Event::Reply(reply))
    }

    /// Drives along y = 10 from `from` to `to` at 1 m/s, starting every operation that is
    /// due at once and confirming it at once; the operations, in order.
    fn drive_to(&mut self, from: f64, to: f64) -> Vec<Operation> {
        let mut sent = Vec::new();
        let mut x = from;
        while x <= to + 1e-9 {
            let actions = self.sample(x);
            assert!(actions.is_empty(), "at x = {x}: {actions:?}");
            while let Some(op) = self.next() {
                sent.push(op);
                if self.drive.phase() != Phase::Extending {
                    assert!(self.reply(Reply::Done).is_empty());
                }
            }
            x += 0.05;
        }
        sent
    }
}

fn append_index(op: &Operation) -> Option<usize> {
    match op {
        Operation::AppendSegment { command_index, .. } => Some(*command_index),
        _ => None,
    }
}

#[test]
fn nothing_is_sent_before_the_first_sample() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    assert_eq!(h.next(), None);
    assert_eq!(h.drive.phase(), Phase::Commands);
    assert!(h.sample(2.0).is_empty());
    assert_eq!(h.next(), None, "6.7 s from the stopping point");
}

#[test]
fn the_first_segment_is_appended_when_the_time_to_the_end_falls_to_the_lead_time() {
    let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    // The car stops 1.323 m before x = 10 (look-ahead at 1 m/s); the lead time is 1.02 s.
    h.sample(7.6);
    assert_eq!(h.next(), None, "1.077 s left");
    h.sample(7.7);
    let Some(Operation::AppendSegment {
        command_index,
        points,
    }) = h.next()
    else {
        panic!("no segment appended with 0.977 s left");
    };
    assert_eq!(command_index, 0);
    let xs: Vec<f64> = points.iter().map(|w| w.position.x).collect();
    assert_eq!(xs, [12.0, 14.0, 16.0, 18.0]);
    assert!(points.iter().all(|w| w.speed == 1.0));
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.streaming.appends.len(), 1);
    assert_eq!(outcome.streaming.appends[0].lead, 1020);
    assert_eq!(outcome.streaming.appends[0].confirmed_after, None);
}

#[test]
fn the_next_segment_waits_for_the_previous_one_to_be_confirmed() {
    let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
    // Segment 0 is still on its way: nothing else goes out, however late it gets.
    h.sample(15.7);
    assert_eq!(h.next(), None);
    h.now += ms(30);
    assert!(h.reply(Reply::Done).is_empty());
    assert_eq!(h.next().as_ref().and_then(append_index), Some(1));
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.streaming.appends[0].confirmed_after, Some(80));
}

#[test]
fn after_an_append_the_next_decision_waits_for_a_sample() {
    let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert!(h.next().is_some());
    assert!(h.reply(Reply::Done).is_empty());
    assert_eq!(h.next(), None, "no sample located on the new route yet");
    h.sample(7.75);
    assert_eq!(h.next(), None, "7.9 s left of the new route");
}

fn placed_fault(probe: Probe, segment_index: usize, along_m: f64) -> Command {
    let Command::AddFault(mut fault) = fault(probe) else {
        unreachable!()
    };
    fault.at = Some(FaultPlace {
        segment_index,
        along_m,
    });
    Command::AddFault(fault)
}

fn fault_index(op: &Option<Operation>) -> Option<(usize, usize)> {
    match op {
        Some(Operation::AddFault {
            command_index,
            on_probe,
            ..
        }) => Some((*command_index, *on_probe)),
        _ => None,
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn faults_without_a_place_go_out_when_four_points_are_left_of_their_segment() {
    let commands = vec![
        segment(12.0),
        fault(Probe::UwbYaw),
        fault(Probe::UwbYaw),
        segment(20.0),
    ];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
    assert!(h.reply(Reply::Done).is_empty());
    // Segment 0 is x = 12 … 18 (route points 5-8): 4 points left once the car reaches point 5,
    // x = 12, 2 m along the segment. The car is at x = 11 at 90 ms (the sample, 20 ms round
    // trip, arrives at 100 ms): it gets there at 1.09 s; a command goes 10 ms before. Both
    // faults have that place and go together, one probe's commands in flight at once; the
    // second counts the first as on the probe when its reply is lost (the car adds in order).
    h.sample(11.0);
    assert_eq!(h.drive.next_fault(h.now), None);
    assert_eq!(h.drive.fault_due(), Some(ms(1080)));
    h.now = ms(1080);
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((1, 0)));
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((2, 1)));
    assert_eq!(h.drive.fault_due(), None);
    h.now += ms(20);
    let confirmed = |command_index| Event::FaultReply {
        command_index,
        reply: Reply::Done,
        resent: false,
    };
    assert!(h.drive.handle(h.now, confirmed(1)).is_empty());
    assert!(h.drive.handle(h.now, confirmed(2)).is_empty());
    h.now = ms(1150);
    h.sample(12.1);
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.faults_confirmed, [(1, ms(1090)), (2, ms(1090))]);
    let places = &outcome.fault_places;
    assert_eq!(places.len(), 2);
    assert!(places.iter().all(|p| p.rule == PlaceRule::EarlierTool));
    assert!(places.iter().all(|p| close(p.planned_along_m, 2.0)));
    let errors: Vec<f64> = places.iter().map(|p| p.error_m.unwrap()).collect();
    assert!(errors.iter().all(|&e| close(e, 0.0)), "{errors:?}");
    // Probe calls every 10 ms from when the car added it, 50 of them.
    assert!(close(places[0].acts_from_s, 1.09) && close(places[0].acts_to_s, 1.59));
}

#[test]
fn faults_on_different_probes_are_in_flight_together_each_at_its_place() {
    // Two faults placed 0.01 m apart (10 ms at 1 m/s, less than the 20 ms round trip), on two
    // probes: neither waits for the other.
    let commands = vec![
        segment(12.0),
        placed_fault(Probe::UwbRange(50), 0, 3.0),
        placed_fault(Probe::UwbYaw, 0, 3.01),
    ];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
    assert!(h.reply(Reply::Done).is_empty());
    // x = 13 is 3 m along the segment; the car is at x = 12 at 90 ms, at 1 m/s: there at
    // 1.09 s, the command 10 ms before; the second place 10 ms later.
    h.sample(12.0);
    assert_eq!(h.drive.fault_due(), Some(ms(1080)));
    h.now = ms(1080);
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((1, 0)));
    assert_eq!(h.drive.next_fault(h.now), None, "the second is not due yet");
    assert_eq!(h.drive.fault_due(), Some(ms(1090)));
    h.now = ms(1090);
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((2, 0)));
    // Replies in any order.
    for (command_index, at) in [(2, 1110), (1, 1100)] {
        h.now = ms(at);
        let reply = Event::FaultReply {
            command_index,
            reply: Reply::Done,
            resent: false,
        };
        assert!(h.drive.handle(h.now, reply).is_empty());
    }
    let outcome = h.drive.finish(h.now);
    let mut confirmed = outcome.faults_confirmed.clone();
    confirmed.sort();
    assert_eq!(confirmed, [(1, ms(1090)), (2, ms(1100))]);
}

#[test]
fn a_placed_fault_is_sent_half_a_round_trip_before_the_car_reaches_its_place() {
    let commands = vec![segment(12.0), placed_fault(Probe::UwbRange(50), 0, 3.0)];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
    assert!(h.reply(Reply::Done).is_empty());
    // From the last sample (x = 7.7 at 40 ms, 1 m/s) the car reaches x = 13 at 5.34 s.
    assert_eq!(h.drive.fault_due(), Some(ms(5330)));
    // 3 m along the segment (from x = 10) is x = 13; the car is at x = 12 at 90 ms, at its
    // route's 1 m/s: there at 1.09 s, the command 10 ms before.
    h.sample_at(Point::new(12.0, 10.0), 1.0);
    assert_eq!(h.drive.fault_due(), Some(ms(1080)));
    h.now = ms(1080);
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((1, 0)));
    // The reply is lost; the car's list shows the fault: it was added 10 ms after sending.
    h.now = ms(2100);
    let lost = Event::FaultReply {
        command_index: 1,
        reply: Reply::Done,
        resent: true,
    };
    assert!(h.drive.handle(h.now, lost).is_empty());
    h.sample_at(Point::new(14.05, 10.0), 1.0);
    let outcome = h.drive.finish(h.now);
    let place = outcome.fault_places[0];
    assert_eq!(place.rule, PlaceRule::Planned);
    assert!(close(place.added_s, 1.09), "{place:?}");
    // Between x = 12 at 90 ms and x = 14.05 at 2.14 s: x = 13.0 at 1.09 s.
    assert!(place.error_m.unwrap().abs() < 0.01, "{place:?}");
}

#[test]
fn a_fault_never_delays_a_segment_nor_outlives_a_failure() {
    let commands = vec![
        segment(12.0),
        placed_fault(Probe::UwbYaw, 0, 6.0),
        segment(20.0),
        segment(28.0),
        placed_fault(Probe::UwbYaw, 2, 1.0),
    ];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
    assert!(h.reply(Reply::Done).is_empty());
    // The fault is placed at x = 16, after the point where segment 2 must go (x = 15.7).
    h.sample(15.7);
    assert_eq!(h.next().as_ref().and_then(append_index), Some(2));
    assert_eq!(h.drive.next_fault(h.now), None, "x = 16 is 0.3 s ahead");
    assert!(h.drive.fault_due().is_some());
    assert!(h.reply(Reply::Done).is_empty());
    // A failing segment stops the test: the faults still to come are not sent.
    h.uwb_offset = 2.0;
    h.sample(16.5);
    assert_eq!(fault_index(&h.drive.next_fault(h.now)), Some((1, 0)));
    let confirmed = Event::FaultReply {
        command_index: 1,
        reply: Reply::Done,
        resent: false,
    };
    assert!(h.drive.handle(h.now, confirmed).is_empty());
    h.sample(20.5);
    assert_eq!(h.drive.phase(), Phase::StopPending);
    assert_eq!(h.drive.fault_due(), None);
    assert_eq!(h.drive.next_fault(h.now), None);
}

#[test]
fn a_lossy_link_sends_earlier_by_a_request_timeout() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(6.7);
    assert_eq!(h.next(), None, "1.977 s left");
    let lossy = LinkStatus {
        lossy: true,
        ..LINK
    };
    assert!(h.drive.next_operation(h.now, lossy).is_some());
}

#[test]
fn the_default_policy_stops_at_the_first_failing_segment() {
    let commands = vec![segment(12.0), segment(20.0), segment(28.0)];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::StopAtFailingSegment);
    h.uwb_offset = 2.0;
    let sent = h.drive_to(7.0, 17.95);
    assert_eq!(
        sent.iter().filter_map(append_index).collect::<Vec<_>>(),
        [0, 1]
    );
    assert_eq!(h.drive.phase(), Phase::Commands);
    // Leaving segment 0 judges it: failed, so the safe stop begins.
    h.uwb_offset = 0.0;
    assert!(h.sample(18.05).is_empty());
    assert_eq!(h.drive.phase(), Phase::StopPending);
    let Some(Operation::AppendStop { points }) = h.next() else {
        panic!("no safe stop extension");
    };
    assert_eq!(points.len(), 4);
    assert!(points.iter().all(|w| w.speed == SAFE_STOP_SPEED_MPS));
    assert!(points.iter().all(|w| area.contains_point(w.position)));
    assert_eq!(h.drive.phase(), Phase::Extending);
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.segments.len(), 1, "segment 1 is not judged");
    assert_eq!(outcome.segments[0].oracle.verdict, SegmentVerdict::Failed);
    assert_eq!(outcome.abort, None);
}

#[test]
fn continue_and_record_judges_every_segment() {
    let commands = vec![segment(12.0), segment(20.0), segment(28.0)];
    let (area, plan) = (area(), plan(commands));
    let mut h = Harness::new(&area, &plan, FailurePolicy::ContinueAndRecord);
    h.uwb_offset = 2.0;
    h.drive_to(7.0, 17.95);
    h.uwb_offset = 0.5;
    let sent = h.drive_to(18.0, 27.0);
    assert_eq!(
        sent.iter().filter_map(append_index).collect::<Vec<_>>(),
        [2]
    );
    assert_eq!(h.drive.phase(), Phase::Commands);
    // Segment 2, being driven, is judged on what was seen of it.
    let outcome = h.drive.finish(h.now);
    let verdicts: Vec<SegmentVerdict> = outcome.segments.iter().map(|s| s.oracle.verdict).collect();
    assert_eq!(
        verdicts,
        [
            SegmentVerdict::Failed,
            SegmentVerdict::Passed,
            SegmentVerdict::Passed
        ]
    );
    let commands: Vec<usize> = outcome.segments.iter().map(|s| s.command_index).collect();
    assert_eq!(commands, [0, 1, 2]);
}

#[test]
fn an_interrupt_demands_the_safe_stop_once() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(5.0);
    assert!(h.drive.interruptible());
    let actions = h.drive.handle(h.now, Event::Interrupt);
    let [Action::Stop(abort)] = actions[..] else {
        panic!("{actions:?}");
    };
    assert_eq!(abort.reason, AbortReason::Interrupted);
    assert_eq!(abort.action, StopAction::SafeStop);
    assert!(!h.drive.interruptible());
    assert_eq!(h.drive.phase(), Phase::StopPending);
    assert!(matches!(h.next(), Some(Operation::AppendStop { .. })));
    // A second stop is not recorded again.
    assert!(h.drive.handle(h.now, Event::Interrupt).is_empty());
    assert_eq!(h.drive.abort(), Some(abort));
}

#[test]
fn a_starving_car_demands_the_safe_stop() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(8.0);
    let actions = h.sample(8.7);
    assert!(
        matches!(
            actions[..],
            [Action::Stop(Abort {
                reason: AbortReason::Starved,
                ..
            })]
        ),
        "{actions:?}"
    );
    assert_eq!(h.drive.phase(), Phase::StopPending);
}

#[test]
fn a_car_that_does_not_keep_up_is_stopped_at_the_tests_time_limit() {
    // 8 m of route after the start's end at 1 m/s: 3 × 8 s + 60 s = 84 s.
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    let mut stopped = None;
    while h.now < Duration::from_secs(100) && stopped.is_none() {
        // Standing on the start route, reporting every 50 ms.
        let mut actions = h.sample_at(Point::new(3.0, 10.0), 0.0);
        actions.extend(h.drive.handle(h.now, Event::Tick));
        stopped = actions.into_iter().find_map(|a| match a {
            Action::Stop(abort) => Some((h.now, abort)),
            _ => None,
        });
    }
    let (at, abort) = stopped.expect("stopped");
    assert_eq!(abort.reason, AbortReason::TimeLimit { limit_s: 84.0 });
    assert_eq!(abort.action, StopAction::SafeStop);
    assert!(
        at > Duration::from_secs(84) && at < Duration::from_millis(84_100),
        "{at:?}"
    );
    assert_eq!(
        abort.reason.to_string(),
        "ran past its time limit of 84 s (3 × its planned driving time + 60 s)"
    );
}

#[test]
fn a_braking_abort_abandons_the_operation_in_flight_and_brakes() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert!(h.next().is_some());
    let actions = h.sample_at(Point::new(7.75, 12.0), 1.0);
    let [Action::Stop(abort), Action::Abandon, Action::Brake] = actions[..] else {
        panic!("{actions:?}");
    };
    assert!(matches!(abort.reason, AbortReason::OffRoute { .. }));
    assert_eq!(h.drive.phase(), Phase::Braking);
    assert_eq!(h.next(), None);
}

#[test]
fn a_lost_link_ends_the_drive_at_once() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(5.0);
    let actions = h.drive.handle(h.now, Event::LinkLost);
    assert!(
        matches!(
            actions[..],
            [Action::Stop(Abort {
                reason: AbortReason::LinkLost,
                ..
            })]
        ),
        "{actions:?}"
    );
    assert!(h.drive.is_done());
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.abort_text.as_deref(), Some("link lost"));
    // So does a command that finds it lost, abandoning nothing (the answer came).
    let (area, plan) = (self::area(), self::plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert!(h.next().is_some());
    let actions = h.reply(Reply::LinkLost);
    assert!(matches!(actions[..], [Action::Stop(_)]), "{actions:?}");
    assert!(h.drive.is_done());
}

#[test]
fn a_refused_command_brakes_with_the_reason() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(7.7);
    assert!(h.next().is_some());
    let actions = h.reply(Reply::Failed("no reply".to_owned()));
    assert!(
        matches!(
            actions[..],
            [
                Action::Stop(Abort {
                    reason: AbortReason::CommandRefused { command_index: 0 },
                    ..
                }),
                Action::Brake
            ]
        ),
        "{actions:?}"
    );
    let outcome = h.drive.finish(h.now);
    assert_eq!(
        outcome.abort_text.as_deref(),
        Some("command 0 failed: command 0: no reply")
    );
}

#[test]
fn the_safe_stop_rolls_out_the_extension_then_brakes_until_the_car_stands() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    let sent = h.drive_to(7.0, 15.7);
    assert_eq!(sent.len(), 2, "{sent:?}");
    let Operation::AppendStop { points } = &sent[1] else {
        panic!("{sent:?}");
    };
    // The plan is done: its extension is on its way.
    assert_eq!(h.drive.phase(), Phase::Extending);
    assert!(h.reply(Reply::Done).is_empty());
    assert_eq!(h.drive.phase(), Phase::Rolling);
    // Still rolling on the extension, then at its end: brake.
    assert!(h.sample_at(points[0].position, 0.8).is_empty());
    let end = points[points.len() - 1].position;
    assert_eq!(h.sample_at(end, 0.8), [Action::Brake]);
    assert_eq!(h.drive.phase(), Phase::Braking);
    assert_eq!(h.sample_at(end, 0.3), [Action::Brake]);
    assert!(h.sample_at(end, 0.05).is_empty());
    assert!(h.drive.is_done());
    let outcome = h.drive.finish(h.now);
    assert_eq!(outcome.abort, None);
    assert_eq!(outcome.segments.len(), 1);
    assert_eq!(outcome.segments[0].oracle.verdict, SegmentVerdict::Passed);
    assert_eq!(outcome.streaming.appends.len(), 2);
    assert!(outcome.streaming.starvations_ms.is_empty());
}

#[test]
fn the_safe_stop_brakes_at_once_when_the_car_already_stands() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(5.0);
    h.drive.handle(h.now, Event::Interrupt);
    assert!(matches!(h.next(), Some(Operation::AppendStop { .. })));
    assert!(h.reply(Reply::Done).is_empty());
    assert_eq!(h.sample_at(Point::new(5.0, 10.0), 0.0), [Action::Brake]);
    assert_eq!(h.drive.phase(), Phase::Braking);
}

#[test]
fn braking_gives_up_after_5_s() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.sample(5.0);
    let actions = h.sample_at(Point::new(5.05, 13.0), 1.0);
    assert_eq!(actions.len(), 2, "{actions:?}");
    let braking_at = h.now;
    while h.now + ms(50) < braking_at + BRAKE_TIMEOUT {
        assert_eq!(h.sample_at(Point::new(5.05, 13.0), 1.0), [Action::Brake]);
        assert!(h.drive.handle(h.now, Event::Tick).is_empty());
    }
    assert!(!h.drive.is_done());
    h.now = braking_at + BRAKE_TIMEOUT;
    assert!(h.drive.handle(h.now, Event::Tick).is_empty());
    assert!(h.drive.is_done());
    let text = h.drive.finish(h.now).abort_text.unwrap();
    assert!(
        text.ends_with(
            "off the planned route at (5.05, 13.00): the car did not stop within 5 s of braking"
        ),
        "{text}"
    );
}

#[test]
fn a_drive_stopped_before_the_start_is_aborted_with_no_segment() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let mut h = Harness::new(&area, &plan, FailurePolicy::default());
    h.drive
        .end_before_start(Some(Abort::new(AbortReason::LinkLost, Duration::ZERO)));
    assert!(h.drive.is_done());
    let outcome = h.drive.finish(Duration::ZERO);
    assert!(outcome.segments.is_empty());
    assert_eq!(outcome.abort_text.as_deref(), Some("link lost"));
    let judged: Vec<JudgedSegment> = Vec::new();
    assert_eq!(
        test_verdict(&judged, outcome.abort_text.as_deref()).verdict,
        Verdict::Aborted
    );
}

#[test]
fn the_safe_stop_extension_is_the_same_for_the_same_seed() {
    let (area, plan) = (area(), plan(vec![segment(12.0)]));
    let extension = || {
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(5.0);
        h.drive.handle(h.now, Event::Interrupt);
        h.next()
    };
    assert_eq!(extension(), extension());
}
