//! The statistics of a comparison: McNemar's exact test on the discordant test verdicts, the
//! median with a cluster bootstrap over tests, and nearest-rank quantiles.

use rand::RngExt;

use crate::seed;

/// McNemar's exact test, two-sided: the probability, were a discordant pair as likely to go
/// either way (Binomial(b + c, ½)), of a split at least as uneven as `b` against `c`:
/// `min(1, 2·P(X ≤ min(b, c)))`. 1 when there is no discordant pair or `b = c`.
///
/// The tail is summed in log space (`ln C(n, k)` built up term by term, the terms added by
/// log-sum-exp), so it is exact to rounding for any `n` (no factorial overflows, no term
/// underflows to zero before it is compared): `n` of 100,000 takes a fraction of a millisecond.
pub fn mcnemar_p(b: u64, c: u64) -> f64 {
    let n = b + c;
    let k = b.min(c);
    if n == 0 || b == c {
        return 1.0;
    }
    let ln2 = std::f64::consts::LN_2;
    let nf = n as f64;
    // ln P(X = i) = ln C(n, i) − n ln 2, for i = 0..=k.
    let mut ln_choose = 0.0f64;
    let mut terms = Vec::with_capacity(k as usize + 1);
    for i in 0..=k {
        if i > 0 {
            let fi = i as f64;
            ln_choose += (nf - fi + 1.0).ln() - fi.ln();
        }
        terms.push(ln_choose - nf * ln2);
    }
    let top = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sum: f64 = terms.iter().map(|t| (t - top).exp()).sum();
    let ln_tail = top + sum.ln();
    (2.0 * ln_tail.exp()).clamp(0.0, 1.0)
}

/// The median of `values` (the mean of the two middle values of an even count); `None` for
/// none. Non-finite values must not be given.
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    Some(if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    })
}

/// The nearest-rank `q`-quantile (0 ≤ q ≤ 1; 0 is the least value) of `sorted` (ascending): the smallest value at
/// least a share `q` of the values do not exceed. `None` for none.
pub fn nearest_rank(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

/// A cluster bootstrap of the median: the resampled medians, sorted, and the sample median.
#[derive(Debug, Clone, PartialEq)]
pub struct Bootstrap {
    /// The median of every value (every cluster once).
    pub median: f64,
    /// The median of each resample, ascending.
    pub medians: Vec<f64>,
    /// The clusters resampled (those with at least one value).
    pub clusters: usize,
}

impl Bootstrap {
    /// A two-sided percentile interval at `level` (0.95: about the 2.5th and 97.5th percentiles
    /// of the resampled medians): the resampled medians of rank `r = ⌈n·(1 − level)/2⌉` (at
    /// least 1) and `n + 1 − r` of the `n` in ascending order, so the interval of the negated
    /// values is exactly the negated interval. Widened to hold the sample median when those miss
    /// it (possible with a handful of clusters): never narrower, so never a false alarm more.
    pub fn interval(&self, level: f64) -> (f64, f64) {
        let n = self.medians.len();
        if n == 0 {
            return (self.median, self.median);
        }
        let tail = ((1.0 - level) / 2.0).clamp(0.0, 0.5);
        let r = ((tail * n as f64 - 1e-9).ceil() as usize).clamp(1, n.div_ceil(2));
        let (lo, hi) = (self.medians[r - 1], self.medians[n - r]);
        (lo.min(self.median), hi.max(self.median))
    }
}

/// The median of the values of `clusters` with a cluster bootstrap: `resamples` times, draw as
/// many clusters as there are, with replacement, and take the median of every value of the
/// clusters drawn. Values of one cluster (the segments of one test) are not independent, so
/// clusters, not values, are resampled. Clusters without a value are left out. Deterministic
/// for `seed` (`campaign::seed::rng`). `None` without any value.
///
/// Fast for large inputs: the values are ranked once; a resample's median is found by counting
/// each rank's weight (its cluster's draws) and walking the counts to the middle, `O(values)`
/// per resample without sorting.
pub fn bootstrap_median(clusters: &[Vec<f64>], resamples: usize, seed: u64) -> Option<Bootstrap> {
    let clusters: Vec<&Vec<f64>> = clusters.iter().filter(|c| !c.is_empty()).collect();
    let mut all: Vec<(f64, usize)> = clusters
        .iter()
        .enumerate()
        .flat_map(|(i, c)| c.iter().map(move |&v| (v, i)))
        .collect();
    if all.is_empty() {
        return None;
    }
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let values: Vec<f64> = all.iter().map(|&(v, _)| v).collect();
    let mut ranks: Vec<Vec<u32>> = vec![Vec::new(); clusters.len()];
    for (rank, &(_, cluster)) in all.iter().enumerate() {
        ranks[cluster].push(rank as u32);
    }
    let sample = weighted_median(&values, &vec![1u32; values.len()], values.len() as u64);
    let mut rng = seed::rng(seed);
    let k = clusters.len();
    let mut draws = vec![0u32; k];
    let mut weights = vec![0u32; values.len()];
    let mut medians = Vec::with_capacity(resamples);
    for _ in 0..resamples {
        draws.iter_mut().for_each(|d| *d = 0);
        for _ in 0..k {
            draws[rng.random_range(0..k)] += 1;
        }
        weights.iter_mut().for_each(|w| *w = 0);
        let mut total = 0u64;
        for (cluster, &d) in draws.iter().enumerate() {
            if d == 0 {
                continue;
            }
            for &r in &ranks[cluster] {
                weights[r as usize] = d;
            }
            total += u64::from(d) * ranks[cluster].len() as u64;
        }
        medians.push(weighted_median(&values, &weights, total));
    }
    medians.sort_by(f64::total_cmp);
    Some(Bootstrap {
        median: sample,
        medians,
        clusters: k,
    })
}

/// The median of `sorted` with each value repeated `weights[i]` times, `total` values in all
/// (at least one).
fn weighted_median(sorted: &[f64], weights: &[u32], total: u64) -> f64 {
    // 0-based ranks of the middle value(s) in the weighted multiset.
    let (a, b) = if total % 2 == 1 {
        (total / 2, total / 2)
    } else {
        (total / 2 - 1, total / 2)
    };
    let mut seen = 0u64;
    let mut low = None;
    for (value, &w) in sorted.iter().zip(weights) {
        if w == 0 {
            continue;
        }
        seen += u64::from(w);
        if low.is_none() && seen > a {
            low = Some(*value);
        }
        if seen > b {
            return (low.unwrap_or(*value) + value) / 2.0;
        }
    }
    // Unreachable for a consistent `total`; the largest value is the safe answer.
    sorted.last().copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    /// P(X ≤ k) for Binomial(n, ½) by exact rational arithmetic in u128 (small n).
    fn exact_tail(n: u64, k: u64) -> f64 {
        let mut c: u128 = 1;
        let mut sum: u128 = 0;
        for i in 0..=k {
            if i > 0 {
                c = c * u128::from(n - i + 1) / u128::from(i);
            }
            sum += c;
        }
        sum as f64 / 2f64.powi(n as i32)
    }

    #[test]
    fn mcnemar_matches_the_exact_binomial_for_small_counts() {
        for n in 1..=60u64 {
            for b in 0..=n {
                let c = n - b;
                let expected = if b == c {
                    1.0
                } else {
                    (2.0 * exact_tail(n, b.min(c))).min(1.0)
                };
                let p = mcnemar_p(b, c);
                assert!(
                    (p - expected).abs() <= 1e-12 * expected.max(1e-300) + 1e-15,
                    "b={b} c={c}: {p} against {expected}"
                );
            }
        }
        // Textbook values: 0 against 6 gives 2/64; 1 against 9, 22/1024.
        assert!((mcnemar_p(0, 6) - 0.031_25).abs() < 1e-15);
        assert!((mcnemar_p(9, 1) - 22.0 / 1024.0).abs() < 1e-15);
    }

    #[test]
    fn mcnemar_works_for_a_hundred_thousand_discordant_pairs() {
        // Balanced within one standard deviation (√n / 2 ≈ 158): far from significant.
        let p = mcnemar_p(50_100, 49_900);
        assert!(p > 0.2 && p < 1.0, "{p}");
        // Five standard deviations: p ≈ 5.7e-7 (normal approximation 5.73e-7).
        let p = mcnemar_p(50_791, 49_209);
        assert!(p > 3e-7 && p < 9e-7, "{p}");
        // Far in the tail, still a positive number, not 0 by underflow of each term.
        let p = mcnemar_p(52_000, 48_000);
        assert!(p > 0.0 && p < 1e-30, "{p}");
        // 2 · 2^−100000 is below the least f64: it rounds to 0.
        assert_eq!(mcnemar_p(0, 100_000), 0.0);
    }

    #[test]
    fn the_median_and_nearest_rank() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        let sorted: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(nearest_rank(&sorted, 0.95), Some(19.0));
        assert_eq!(nearest_rank(&sorted, 1.0), Some(20.0));
        assert_eq!(nearest_rank(&sorted, 0.01), Some(1.0));
    }

    #[test]
    fn the_bootstrap_interval_covers_a_shift_and_resamples_tests_not_segments() {
        // 200 tests of 5 segments each, every segment of test t changed by a test-wide amount
        // around +0.1 m: the interval is about the test-level spread / √200, not /√1000.
        let clusters: Vec<Vec<f64>> = (0..200)
            .map(|t| {
                let shift = 0.1 + 0.05 * (((t * 37) % 21) as f64 - 10.0) / 10.0;
                (0..5).map(|s| shift + 0.001 * s as f64).collect()
            })
            .collect();
        let b = bootstrap_median(&clusters, 2000, 7).unwrap();
        let (lo, hi) = b.interval(0.95);
        assert!(
            lo > 0.08 && lo < b.median && b.median < hi && hi < 0.12,
            "{lo} {hi}"
        );
        assert_eq!(b.clusters, 200);
        assert_eq!(b.medians.len(), 2000);
        assert!(bootstrap_median(&[vec![], vec![]], 10, 1).is_none());
    }

    #[test]
    fn the_weighted_median_walks_to_the_middle() {
        let v = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(weighted_median(&v, &[1, 1, 1, 1], 4), 2.5);
        assert_eq!(weighted_median(&v, &[3, 0, 0, 1], 4), 1.0);
        assert_eq!(weighted_median(&v, &[2, 0, 0, 2], 4), 2.5);
        assert_eq!(weighted_median(&v, &[0, 0, 1, 0], 1), 3.0);
    }

    proptest! {
        #[test]
        fn mcnemar_is_a_probability_symmetric_and_one_when_balanced(b in 0u64..3000, c in 0u64..3000) {
            let p = mcnemar_p(b, c);
            prop_assert!((0.0..=1.0).contains(&p));
            prop_assert_eq!(p, mcnemar_p(c, b));
            prop_assert_eq!(mcnemar_p(b, b), 1.0);
            // A more uneven split is never less significant.
            if b < c {
                prop_assert!(mcnemar_p(b, c + 1) <= p);
            }
        }

        #[test]
        fn the_bootstrap_is_deterministic_and_its_interval_holds_the_median(
            clusters in prop::collection::vec(prop::collection::vec(-2.0f64..2.0, 0..6), 1..25),
            seed in any::<u64>(),
        ) {
            let a = bootstrap_median(&clusters, 200, seed);
            let b = bootstrap_median(&clusters, 200, seed);
            prop_assert_eq!(&a, &b);
            let all: Vec<f64> = clusters.iter().flatten().copied().collect();
            match a {
                None => prop_assert!(all.is_empty()),
                Some(boot) => {
                    prop_assert_eq!(Some(boot.median), median(&all));
                    for level in [0.5, 0.95, 0.975] {
                        let (lo, hi) = boot.interval(level);
                        prop_assert!(lo <= boot.median && boot.median <= hi);
                        let min = all.iter().copied().fold(f64::INFINITY, f64::min);
                        let max = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                        prop_assert!(lo >= min && hi <= max);
                    }
                }
            }
        }
    }
}
