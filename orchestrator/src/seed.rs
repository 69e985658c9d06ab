//! Seeds and random number generators: one seed determines a whole run.
//!
//! Every command that draws random numbers takes `--seed`; without it a seed is drawn from the
//! operating system's entropy and printed, so any run can be repeated.

use rand::SeedableRng;

/// The random number generator of every drivecheck run: small, fast, portable and reproducible
/// across platforms for a given seed.
pub type RunRng = rand_pcg::Pcg64Mcg;

/// The seed to use: the one given, or a fresh one from the operating system.
pub fn choose_seed(given: Option<u64>) -> u64 {
    given.unwrap_or_else(rand::random)
}

/// The run's generator for `seed`.
pub fn rng(seed: u64) -> RunRng {
    RunRng::seed_from_u64(seed)
}
