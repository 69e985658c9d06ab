//! Random number generators: one seed determines a whole run.

use rand::SeedableRng;

/// The random number generator of every drivecheck run: small, fast, portable and reproducible
/// across platforms for a given seed.
pub type RunRng = rand_pcg::Pcg64Mcg;

/// The run's generator for `seed`.
pub fn rng(seed: u64) -> RunRng {
    RunRng::seed_from_u64(seed)
}
