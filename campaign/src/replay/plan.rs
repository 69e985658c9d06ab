//! Replay planning: the test a recorded case is driven as.

use scenarios::Scenario;
use trajgen::{Generator, Point};

use car_link::firmware::{FAULT_PROBES, FAULTS_PER_PROBE, Param};

use crate::files::{Case, CaseError, CommandRecord, RoutePointRecord, invalid};
use crate::model::{Probe, TestPlan, start_tail};

/// How far past a segment's computed length a written place may lie (rounding).
const PLACE_TOLERANCE_M: f64 = 1e-3;

impl Case {
    /// The plan a replay drives as test `test_index`: the recorded commands (without the fault
    /// commands when `no_faults`) from the end of `scenario`'s start route. Checks the values
    /// ([`Case::check`]) and that every segment is drivable in `scenario`
    /// ([`Case::check_route`]) first: a car is never sent a route that leaves the area. A
    /// segment without a recorded ahead margin (written by hand) gets one from `generator`
    /// (seeded with `seed`), or the case is refused: the car must always be able to stop inside
    /// the area.
    pub fn replay_plan(
        &self,
        scenario: &Scenario,
        generator: &Generator,
        seed: u64,
        no_faults: bool,
        test_index: usize,
    ) -> Result<TestPlan, CaseError> {
        self.check()?;
        self.check_route(scenario)?;
        self.check_faults_act(scenario)?;
        let case = self.with_margins(scenario, generator, seed)?;
        case.check_route(scenario)?;
        if !self
            .commands
            .iter()
            .any(|c| matches!(c, CommandRecord::RunSegments { .. }))
        {
            return Err(invalid("commands", "no run_segments command to drive"));
        }
        let start_tail = start_tail(scenario)?;
        let commands = case
            .commands
            .iter()
            .filter(|c| !(no_faults && matches!(c, CommandRecord::AddFault { .. })))
            .map(CommandRecord::to_command)
            .collect();
        Ok(TestPlan {
            test_index,
            start_tail,
            commands,
        })
    }
}

impl Case {
    /// Refuses, before anything is driven, a fault that cannot act as written: a range fault on
    /// an anchor the scenario does not have, a bitflip of a bit outside 0–31 (the firmware would
    /// clamp it to another bit), more faults on a probe or more probes than the firmware's slots
    /// hold (the extra fault would be refused mid-test), a place beyond the end of its segment.
    pub fn check_faults_act(&self, scenario: &Scenario) -> Result<(), CaseError> {
        let mut per_probe: Vec<(Probe, usize)> = Vec::new();
        let mut tail = start_tail(scenario)?;
        let mut lengths = Vec::new();
        for (i, command) in self.commands.iter().enumerate() {
            let path = format!("commands[{i}]");
            let (probe, kind, param, at) = match command {
                CommandRecord::RunSegments { points, .. } => {
                    let points: Vec<Point> =
                        points.iter().map(RoutePointRecord::position).collect();
                    let mut previous = tail.end;
                    let mut length = 0.0;
                    for &p in &points {
                        length += previous.dist(p);
                        previous = p;
                    }
                    lengths.push(length);
                    tail = tail.advanced(&points);
                    continue;
                }
                CommandRecord::AddFault {
                    probe,
                    kind,
                    param,
                    at,
                    ..
                } => (*probe, *kind, *param, *at),
            };
            if let Probe::UwbRange(id) = probe
                && !scenario.anchors.iter().any(|a| u16::from(a.id) == id)
            {
                let known: Vec<String> =
                    scenario.anchors.iter().map(|a| a.id.to_string()).collect();
                return Err(invalid(
                    format!("{path}.probe"),
                    format!(
                        "the scenario has no anchor {id} (its anchors: {}): the fault could never act",
                        if known.is_empty() {
                            "none".to_owned()
                        } else {
                            known.join(", ")
                        }
                    ),
                ));
            }
            if kind.spec().param == Param::Bit
                && !(param.fract() == 0.0 && (0.0..=31.0).contains(&param))
            {
                return Err(invalid(
                    format!("{path}.param"),
                    format!("bitflip bit {param}: a binary32 value has bits 0 to 31"),
                ));
            }
            let probes = per_probe.len();
            match per_probe.iter_mut().find(|(p, _)| *p == probe) {
                Some((_, n)) if *n >= FAULTS_PER_PROBE => {
                    return Err(invalid(
                        format!("{path}.probe"),
                        format!(
                            "a {FAULTS_PER_PROBE}th fault on {probe} already: the firmware holds \
                             {FAULTS_PER_PROBE} faults per probe and would refuse this one"
                        ),
                    ));
                }
                Some((_, n)) => *n += 1,
                None if probes >= FAULT_PROBES => {
                    return Err(invalid(
                        format!("{path}.probe"),
                        format!(
                            "{probe} would be a {}th probe: the firmware holds faults on \
                             {FAULT_PROBES} probes and would refuse this one",
                            FAULT_PROBES + 1
                        ),
                    ));
                }
                None => per_probe.push((probe, 1)),
            }
            if let Some(at) = at
                && let Some(&length) = lengths.get(at.segment_index)
                && at.along_m > length + PLACE_TOLERANCE_M
            {
                return Err(invalid(
                    format!("{path}.at.along_m"),
                    format!(
                        "{} m is beyond the end of segment {} ({length:.3} m long)",
                        at.along_m, at.segment_index
                    ),
                ));
            }
        }
        Ok(())
    }

    /// This case with an ahead margin generated after every segment that has none: one more
    /// point and its margin, proven inside the area from the route as it stands after the
    /// segment.
    pub(crate) fn with_margins(
        &self,
        scenario: &Scenario,
        generator: &Generator,
        seed: u64,
    ) -> Result<Case, CaseError> {
        let mut tail = start_tail(scenario)?;
        let mut rng = crate::seed::rng_for(seed, crate::seed::Purpose::Margins);
        let mut case = self.clone();
        for (command, record) in case.commands.iter_mut().enumerate() {
            let CommandRecord::RunSegments { points, margin, .. } = record else {
                continue;
            };
            let driven: Vec<Point> = points.iter().map(RoutePointRecord::position).collect();
            tail = tail.advanced(&driven);
            if !margin.is_empty() {
                continue;
            }
            let extension = generator
                .extend(&scenario.area, &tail, 1, &mut rng)
                .map_err(|error| CaseError::NoAheadMargin { command, error })?;
            *margin = extension
                .points
                .iter()
                .chain(&extension.margin)
                .map(|&p| p.into())
                .collect();
        }
        Ok(case)
    }
}

#[cfg(test)]
mod tests {
    use trajgen::check_route;

    use super::*;
    use crate::files::tests::{doc_examples, scenario};
    use crate::model::FaultKind;

    #[test]
    fn a_hand_written_case_gets_a_proven_ahead_margin_for_every_segment() {
        let case = Case::from_json(doc_examples()[0]).unwrap();
        let s = scenario(&case.scenario.name);
        let generator =
            Generator::new(s.generator.generator_config(trajgen::Strategy::Wedge)).unwrap();
        let plan = case.replay_plan(&s, &generator, 1, false, 4).unwrap();
        assert_eq!(plan.test_index, 4);
        assert_eq!(plan.commands.len(), case.commands.len());
        let mut tail = plan.start_tail;
        for (_, segment) in plan.segments() {
            assert_eq!(segment.margin.len(), s.generator.ahead_margin + 1);
            assert!(segment.intent.is_none());
            assert!(segment.speeds.iter().all(|&v| v == 1.5));
            let route: Vec<Point> = std::iter::once(tail.end)
                .chain(segment.points.iter().copied())
                .chain(segment.margin.iter().copied())
                .collect();
            assert!(check_route(&s.area, &route, &s.constraints(), Some(tail.heading)).is_ok());
            tail = tail.advanced(&segment.points);
        }
        let without = case.replay_plan(&s, &generator, 1, true, 0).unwrap();
        assert_eq!(without.commands.len(), 3);
        assert_eq!(without.faults().count(), 0);
    }

    #[test]
    fn a_fault_that_cannot_act_is_refused_before_driving() {
        let case = Case::from_json(doc_examples()[0]).unwrap();
        let s = scenario(&case.scenario.name);
        assert_eq!(case.check_faults_act(&s).map_err(|e| e.to_string()), Ok(()));
        let first_fault = case
            .commands
            .iter()
            .position(|c| matches!(c, CommandRecord::AddFault { .. }))
            .expect("the example has a fault");
        let with = |edit: &dyn Fn(&mut CommandRecord)| {
            let mut c = case.clone();
            edit(&mut c.commands[first_fault]);
            c.check_faults_act(&s).map_err(|e| e.to_string())
        };
        let unknown_anchor = with(&|c| {
            if let CommandRecord::AddFault { probe, .. } = c {
                *probe = Probe::UwbRange(77);
            }
        });
        assert!(
            unknown_anchor
                .as_ref()
                .is_err_and(|e| e.contains("no anchor 77")),
            "{unknown_anchor:?}"
        );
        let bit_99 = with(&|c| {
            if let CommandRecord::AddFault { kind, param, .. } = c {
                *kind = FaultKind::Bitflip;
                *param = 99.0;
            }
        });
        assert!(bit_99.is_err_and(|e| e.contains("bits 0 to 31")));
        let far = with(&|c| {
            if let CommandRecord::AddFault { at, .. } = c {
                *at = Some(crate::files::PlaceRecord {
                    segment_index: 0,
                    along_m: 500.0,
                });
            }
        });
        assert!(far.is_err_and(|e| e.contains("beyond the end of segment 0")));
        // Six faults on one probe: the sixth is refused.
        let mut crowded = case.clone();
        let fault = case.commands[first_fault].clone();
        for _ in 0..FAULTS_PER_PROBE {
            crowded.commands.insert(first_fault, fault.clone());
        }
        let error = crowded.check_faults_act(&s).map_err(|e| e.to_string());
        assert!(error.is_err_and(|e| e.contains("5 faults per probe")));
    }
}
