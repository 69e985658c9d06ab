//! The generation half of `proptest-state-machine`'s `Sequential` strategy (0.9.0,
//! `src/strategy.rs`; Copyright 2023 The proptest developers, MIT OR Apache-2.0, as this crate):
//! an initial state, then transitions drawn one at a time from the strategy of the current
//! state, each kept when the preconditions allow it in that state. [`Sequential::generate`] draws
//! from the runner exactly as the crate's `new_tree` does, so a seed gives the same commands it
//! gave through the crate.
//!
//! Why not the crate: it depends on proptest with its `fork` and `timeout` features, which put
//! `rusty-fork`, `tempfile` and `wait-timeout` (processes, files, a clock) into this pure crate's
//! normal dependency tree (ARCHITECTURE.md). Why not its value tree: drivecheck does not shrink
//! through proptest; shrinking is `crate::shrink`'s, which edits a recorded case.

use proptest::collection::SizeRange;
use proptest::num::sample_uniform_incl;
use proptest::strategy::{Strategy, ValueTree};
use proptest::test_runner::{Reason, TestRunner};

/// Whether a transition may follow in a state.
type Precondition<State, Transition> = Box<dyn Fn(&State, &Transition) -> bool + Send + Sync>;
/// The state after a transition.
type Next<State, Transition> = Box<dyn Fn(State, &Transition) -> State + Send + Sync>;

/// A sequence of transitions of a reference state machine, and how to draw it.
pub struct Sequential<State, Transition, StateStrategy, TransitionStrategy> {
    size: SizeRange,
    init_state: Box<dyn Fn() -> StateStrategy + Send + Sync>,
    preconditions: Precondition<State, Transition>,
    transitions: Box<dyn Fn(&State) -> TransitionStrategy + Send + Sync>,
    next: Next<State, Transition>,
}

impl<State, Transition, StateStrategy, TransitionStrategy>
    Sequential<State, Transition, StateStrategy, TransitionStrategy>
where
    State: Clone,
    StateStrategy: Strategy<Value = State>,
    TransitionStrategy: Strategy<Value = Transition>,
{
    /// A sequence of a length in `size`, from the initial state `init_state` draws, of
    /// transitions `transitions` draws in each state, kept where `preconditions` allow them;
    /// `next` is the state after a transition.
    pub fn new(
        size: SizeRange,
        init_state: impl Fn() -> StateStrategy + 'static + Send + Sync,
        preconditions: impl Fn(&State, &Transition) -> bool + 'static + Send + Sync,
        transitions: impl Fn(&State) -> TransitionStrategy + 'static + Send + Sync,
        next: impl Fn(State, &Transition) -> State + 'static + Send + Sync,
    ) -> Self {
        Self {
            size,
            init_state: Box::new(init_state),
            preconditions: Box::new(preconditions),
            transitions: Box::new(transitions),
            next: Box::new(next),
        }
    }

    /// The initial state and the transitions, drawn from `runner`: the length first, then each
    /// transition; a transition the preconditions refuse counts as one of the runner's local
    /// rejections (an error once it has had too many).
    pub fn generate(&self, runner: &mut TestRunner) -> Result<(State, Vec<Transition>), Reason> {
        let initial = (self.init_state)().new_tree(runner)?.current();
        let (min_size, end) = self.size.start_end_incl();
        let length = sample_uniform_incl(runner, min_size, end);
        let mut transitions = Vec::with_capacity(length);
        let mut state = initial.clone();
        while transitions.len() < length {
            let transition = (self.transitions)(&state).new_tree(runner)?.current();
            if (self.preconditions)(&state, &transition) {
                state = (self.next)(state, &transition);
                transitions.push(transition);
            } else {
                runner.reject_local("Pre-conditions were not satisfied")?;
            }
        }
        Ok((initial, transitions))
    }
}
