//! Order statistics shared by the workspace: the nearest-rank percentile.
//!
//! Every percentile drivecheck reports (the oracle's p95, the streaming rule's p99 of round trips
//! and generation times, area validation's p99 of outer tries, the bench tables, the simulator's
//! acceptance figures) is this one definition. `car-link` keeps its own copy for its link health
//! because it depends on no other crate of the workspace.

/// The nearest-rank percentile `q` (0..=1) of ascending `sorted`: the smallest value that at
/// least `q` of the values do not exceed, i.e. the value of rank `⌈q · n⌉` (at least rank 1,
/// so `q = 0` gives the smallest value and `q = 1` the largest); `None` when `sorted` is empty.
pub fn nearest_rank<T: Copy>(sorted: &[T], q: f64) -> Option<T> {
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted.get(rank.clamp(1, sorted.len().max(1)) - 1).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rank_is_the_ceiling_of_q_times_n() {
        let v: Vec<u32> = (1..=200).collect();
        assert_eq!(nearest_rank(&v, 0.99), Some(198));
        assert_eq!(nearest_rank(&v, 0.5), Some(100));
        let v: Vec<u32> = (1..=20).collect();
        assert_eq!(nearest_rank(&v, 0.95), Some(19));
        assert_eq!(nearest_rank(&[1, 2, 3, 4], 0.95), Some(4));
    }

    #[test]
    fn the_ends_are_the_smallest_and_the_largest_value() {
        let v = [0.5, 1.5, 2.5];
        assert_eq!(nearest_rank(&v, 0.0), Some(0.5));
        assert_eq!(nearest_rank(&v, 1.0), Some(2.5));
        assert_eq!(nearest_rank(&[7], 0.99), Some(7));
    }

    #[test]
    fn no_values_have_no_percentile() {
        assert_eq!(nearest_rank::<u32>(&[], 0.99), None);
        assert_eq!(nearest_rank::<f64>(&[], 0.0), None);
    }
}
