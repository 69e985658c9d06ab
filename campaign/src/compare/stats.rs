//! The statistics of a comparison: McNemar's exact test on the discordant test verdicts, the
//! median with a cluster bootstrap over tests (its interval), a sign-flip randomization test of
//! the median over tests (its significance), and nearest-rank quantiles.

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

/// A sign-flip randomization test of the median: the median of every value and its two-sided p.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignFlip {
    /// The median of every value (every cluster once).
    pub median: f64,
    /// The two-sided p: the share of sign assignments whose median is at least as far from 0.
    pub p: f64,
    /// Sign assignments drawn (every one of the `2^k` when that is at most the flips asked).
    pub flips: usize,
    /// Whether every assignment was counted (`p` exact) rather than drawn.
    pub exhaustive: bool,
    /// The clusters (those with at least one value).
    pub clusters: usize,
}

/// Is the median of the values of `clusters` further from 0 than chance makes it? A sign-flip
/// randomization test over clusters: were NEW no different from BASE, which of the two runs of
/// a test is called BASE would not matter, so the changes of one test (NEW − BASE, one cluster)
/// could as well all have the opposite sign. Each of `flips` assignments negates every value of
/// each cluster with probability ½ (a cluster's values together: they are not independent) and
/// takes the median of all values; `p = (1 + #{|median*| ≥ |median|}) / (flips + 1)`, which never
/// exceeds α more often than α when the runs are exchangeable, whatever the distribution or the
/// number of tests. With `k` clusters and `2^k ≤ flips` every assignment is counted once instead
/// and `p = #{|median*| ≥ |median|} / 2^k` exactly. A median of 0 gives `p = 1`. Clusters without
/// a value are left out; `None` without any value. Deterministic for `seed`.
///
/// Fast for large inputs: every value and its negation are ranked once; an assignment puts
/// weight 1 on one of each pair and walks the weights to the middle, `O(values)` per assignment.
pub fn sign_flip_median(clusters: &[Vec<f64>], flips: usize, seed: u64) -> Option<SignFlip> {
    let clusters: Vec<&Vec<f64>> = clusters.iter().filter(|c| !c.is_empty()).collect();
    let count: usize = clusters.iter().map(|c| c.len()).sum();
    if count == 0 {
        return None;
    }
    // Every value (sign +) and its negation (sign −), ranked together.
    let mut all: Vec<(f64, usize, bool)> = clusters
        .iter()
        .enumerate()
        .flat_map(|(i, c)| c.iter().flat_map(move |&v| [(v, i, true), (-v, i, false)]))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let values: Vec<f64> = all.iter().map(|&(v, _, _)| v).collect();
    let k = clusters.len();
    let mut ranks: Vec<[Vec<u32>; 2]> = vec![[Vec::new(), Vec::new()]; k];
    for (rank, &(_, cluster, kept)) in all.iter().enumerate() {
        ranks[cluster][usize::from(!kept)].push(rank as u32);
    }
    let total = count as u64;
    let mut weights = vec![0u32; values.len()];
    let mut median_of = |negated: &mut dyn FnMut(usize) -> bool| -> f64 {
        weights.iter_mut().for_each(|w| *w = 0);
        for (cluster, pair) in ranks.iter().enumerate() {
            for &r in &pair[usize::from(negated(cluster))] {
                weights[r as usize] = 1;
            }
        }
        weighted_median(&values, &weights, total)
    };
    let observed = median_of(&mut |_| false);
    if observed == 0.0 {
        return Some(SignFlip {
            median: observed,
            p: 1.0,
            flips: 0,
            exhaustive: true,
            clusters: k,
        });
    }
    let far = |m: f64| m.abs() >= observed.abs();
    let exhaustive = k < usize::BITS as usize - 1 && (1usize << k) <= flips.max(1);
    let (extreme, drawn) = if exhaustive {
        let n = 1usize << k;
        let extreme = (0..n)
            .filter(|&mask| far(median_of(&mut |c| mask >> c & 1 == 1)))
            .count();
        (extreme, n)
    } else {
        let mut rng = seed::rng(seed);
        let mut signs = vec![false; k];
        let mut extreme = 1; // the observed assignment
        for _ in 0..flips {
            signs.iter_mut().for_each(|s| *s = rng.random_bool(0.5));
            extreme += usize::from(far(median_of(&mut |c| signs[c])));
        }
        (extreme, flips + 1)
    };
    Some(SignFlip {
        median: observed,
        p: extreme as f64 / drawn as f64,
        flips: if exhaustive { drawn } else { flips },
        exhaustive,
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

    /// The sign-flip p by brute force: every assignment, the median by sorting.
    fn brute_sign_flip_p(clusters: &[Vec<f64>]) -> f64 {
        let clusters: Vec<&Vec<f64>> = clusters.iter().filter(|c| !c.is_empty()).collect();
        let all: Vec<f64> = clusters.iter().flat_map(|c| c.iter().copied()).collect();
        let observed = median(&all).unwrap();
        if observed == 0.0 {
            return 1.0;
        }
        let n = 1usize << clusters.len();
        let extreme = (0..n)
            .filter(|mask| {
                let flipped: Vec<f64> = clusters
                    .iter()
                    .enumerate()
                    .flat_map(|(c, v)| {
                        let sign = if mask >> c & 1 == 1 { -1.0 } else { 1.0 };
                        v.iter().map(move |x| sign * x)
                    })
                    .collect();
                median(&flipped).unwrap().abs() >= observed.abs()
            })
            .count();
        extreme as f64 / n as f64
    }

    #[test]
    fn a_few_tests_all_worse_are_not_enough_for_the_sign_flips() {
        // Three tests all worse, median 0.35: of the 8 assignments, all + and all − are as far,
        // and so are the two that flip only the smallest (−0.2, 0.3, 0.4, 0.5): p = 4/8.
        let s = sign_flip_median(&[vec![0.3], vec![0.5, 0.4], vec![0.2]], 2000, 1).unwrap();
        assert!(s.exhaustive);
        assert_eq!((s.flips, s.p, s.median, s.clusters), (8, 0.5, 0.35, 3));
        // Ten tests all worse by about the same: the median (0.1045) does not see the signs of
        // the four values below its two middle ones, so the 16 assignments flipping only those,
        // and their mirrors, are as far: p = 32/1024.
        let ten: Vec<Vec<f64>> = (0..10).map(|t| vec![0.1 + 0.001 * t as f64]).collect();
        let s = sign_flip_median(&ten, 2000, 1).unwrap();
        assert_eq!((s.flips, s.p), (1024, 32.0 / 1024.0));
        assert!(sign_flip_median(&[vec![], vec![]], 10, 1).is_none());
        assert_eq!(
            sign_flip_median(&[vec![0.0, 1.0, -1.0]], 10, 1).unwrap().p,
            1.0
        );
    }

    /// A run of `tests` tests of 6 segments whose changes share a test-wide part: `shift` plus a
    /// symmetric test-wide draw plus a smaller segment draw.
    fn clustered(rng: &mut seed::RunRng, tests: usize, shift: f64) -> Vec<Vec<f64>> {
        (0..tests)
            .map(|_| {
                let common = rng.random_range(-0.3..0.3);
                (0..6)
                    .map(|_| shift + common + rng.random_range(-0.05..0.05))
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_sign_flips_hold_alpha_on_clustered_noise_where_a_segment_bootstrap_would_not() {
        // 400 comparisons without a difference: at α = 0.05 about 20 false alarms; a test that
        // treated the 6 segments of a test as independent would raise far more (its intervals
        // are about √6 too narrow). The bound leaves room for chance: Binomial(400, 0.05)
        // exceeds 32 with probability below 0.3 %.
        let mut rng = seed::rng(11);
        let alarms = (0..400)
            .filter(|&i| {
                let s = sign_flip_median(&clustered(&mut rng, 30, 0.0), 200, i).unwrap();
                s.p < 0.05
            })
            .count();
        assert!(alarms <= 32, "{alarms} false alarms of 400");
        // And it finds a shift of a third of the test-wide spread with 30 tests most times.
        let found = (0..100)
            .filter(|&i| {
                let s = sign_flip_median(&clustered(&mut rng, 30, 0.1), 200, i).unwrap();
                s.p < 0.05 && s.median > 0.0
            })
            .count();
        assert!(found >= 50, "found {found} of 100");
    }

    proptest! {
        #[test]
        fn the_exhaustive_sign_flips_match_a_brute_force_count(
            clusters in prop::collection::vec(prop::collection::vec(-2.0f64..2.0, 0..4), 1..8),
        ) {
            let s = sign_flip_median(&clusters, 1 << 10, 3);
            let any = clusters.iter().any(|c| !c.is_empty());
            prop_assert_eq!(s.is_some(), any);
            if let Some(s) = s {
                prop_assert!(s.exhaustive);
                prop_assert_eq!(s.p, brute_sign_flip_p(&clusters));
                // Negating everything changes nothing but the median's sign.
                let negated: Vec<Vec<f64>> =
                    clusters.iter().map(|c| c.iter().map(|v| -v).collect()).collect();
                let n = sign_flip_median(&negated, 1 << 10, 3).unwrap();
                prop_assert_eq!((n.p, n.median), (s.p, -s.median));
            }
        }

        #[test]
        fn the_drawn_sign_flips_are_a_deterministic_probability(
            clusters in prop::collection::vec(prop::collection::vec(-2.0f64..2.0, 1..4), 12..20),
            seed in any::<u64>(),
        ) {
            let a = sign_flip_median(&clusters, 100, seed).unwrap();
            prop_assert_eq!(a, sign_flip_median(&clusters, 100, seed).unwrap());
            prop_assert!(!a.exhaustive);
            prop_assert_eq!(a.flips, 100);
            prop_assert!(a.p >= 1.0 / 101.0 && a.p <= 1.0);
        }

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
