//! Seeded noise sources: every random draw of the simulation comes from one of these streams.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// An independent, seeded random stream.
#[derive(Debug, Clone)]
pub struct Noise {
    rng: Pcg64Mcg,
}

impl Noise {
    /// The stream `stream` of the simulation seeded with `seed` (streams do not share draws, so
    /// adding draws to one source never shifts another).
    pub fn stream(seed: u64, stream: u64) -> Self {
        let mixed = seed ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        Self {
            rng: Pcg64Mcg::seed_from_u64(mixed),
        }
    }

    /// A uniform draw in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.rng.random::<f64>()
    }

    /// A uniform draw in [lo, hi) (`lo` when the range is empty).
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        if hi > lo {
            lo + (hi - lo) * self.uniform()
        } else {
            lo
        }
    }

    /// A normal draw with mean 0 and standard deviation `sigma` (Box–Muller).
    pub fn gaussian(&mut self, sigma: f64) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.uniform() < p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_draws_and_streams_differ() {
        let a: Vec<f64> = (0..5)
            .map({
                let mut n = Noise::stream(7, 1);
                move |_| n.uniform()
            })
            .collect();
        let b: Vec<f64> = (0..5)
            .map({
                let mut n = Noise::stream(7, 1);
                move |_| n.uniform()
            })
            .collect();
        let c: Vec<f64> = (0..5)
            .map({
                let mut n = Noise::stream(7, 2);
                move |_| n.uniform()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn gaussian_has_the_requested_spread() {
        let mut n = Noise::stream(1, 1);
        let xs: Vec<f64> = (0..20_000).map(|_| n.gaussian(0.1)).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.005, "mean {mean}");
        assert!((var.sqrt() - 0.1).abs() < 0.005, "sd {}", var.sqrt());
    }
}
