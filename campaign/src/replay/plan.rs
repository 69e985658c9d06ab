//! Replay planning: the test a recorded case is driven as.

use scenarios::Scenario;
use trajgen::{Generator, Point};

use crate::case::{Case, CaseError, CommandRecord, RoutePointRecord, invalid};
use crate::model::{TestPlan, start_tail};

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
    /// This case with an ahead margin generated after every segment that has none: one more
    /// point and its margin, proven inside the area from the route as it stands after the
    /// segment.
    fn with_margins(
        &self,
        scenario: &Scenario,
        generator: &Generator,
        seed: u64,
    ) -> Result<Case, CaseError> {
        let mut tail = start_tail(scenario)?;
        let mut rng = crate::seed::rng(seed);
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
    use crate::case::tests::{doc_examples, scenario};

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
}
