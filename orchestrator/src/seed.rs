//! Seeds: one seed determines a whole run.
//!
//! Every command that draws random numbers takes `--seed`; without it a seed is drawn from the
//! operating system's entropy and printed, so any run can be repeated. The generator itself is
//! the campaign core's ([`campaign::seed`]).

pub use campaign::seed::{RunRng, rng};

/// The seed to use: the one given, or a fresh one from the operating system.
pub fn choose_seed(given: Option<u64>) -> u64 {
    given.unwrap_or_else(rand::random)
}
