//! Link health: round-trip times, timeouts, reconnects, and what was thrown away.

use std::collections::VecDeque;
use std::time::Duration;

use tokio::time::Instant;

/// Round trips kept for the percentiles.
const RTT_WINDOW: usize = 1024;

/// A snapshot of a link's health.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LinkHealth {
    /// Whether the link is up now.
    pub link_up: bool,
    /// Median round trip over the last 1024 answered requests.
    pub rtt_p50: Option<Duration>,
    /// 99th-percentile round trip over the same window.
    pub rtt_p99: Option<Duration>,
    /// Answered requests since the start.
    pub answered: u64,
    /// Requests (tries) that timed out since the start.
    pub timeouts: u64,
    /// Successful reconnections since the start.
    pub reconnects: u64,
    /// Replies that matched no waiting request (duplicates, other cars, late answers).
    pub stray_replies: u64,
    /// Replies (other than PRINTF) that came from another car id than this link's car: another
    /// car on a shared link, or a bridge or proxy that changes the id. Counted in
    /// `stray_replies` too.
    pub other_car_replies: u64,
    /// The last of them: which car id it came from, and which this link expected.
    pub last_other_car: Option<OtherCar>,
    /// Candidate frames dropped by the decoder (bad CRC, end byte, length, abandoned).
    pub dropped_frames: u64,
    /// Valid frames whose payload did not decode.
    pub undecodable: u64,
    /// Time since the car last sent a valid frame (`None` before the first). Over UDP, or a TCP connection
    /// whose far end vanished without closing it, a dead car shows here and in the timeouts, since no
    /// connection closes to report it lost.
    pub silent_for: Option<Duration>,
}

/// A reply from another car id than the link's ([`LinkHealth::last_other_car`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OtherCar {
    /// The car id the reply carried.
    pub car: u8,
    /// The car id this link talks to.
    pub expected: u8,
}

impl std::fmt::Display for OtherCar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "a reply came from car id {}, expected {}",
            self.car, self.expected
        )
    }
}

/// Accumulates health figures; snapshots are taken with [`HealthRecorder::snapshot`].
#[derive(Debug, Default)]
pub(crate) struct HealthRecorder {
    /// The window's round trips in the order they ended.
    rtts: VecDeque<Duration>,
    /// The same round trips, sorted: the percentiles are read off it.
    sorted: Vec<Duration>,
    pub(crate) figures: LinkHealth,
    /// When the car last sent a valid frame.
    pub(crate) last_heard: Option<Instant>,
}

impl HealthRecorder {
    pub(crate) fn record_rtt(&mut self, rtt: Duration) {
        // A runner asks for a snapshot at every turn of its loop and a round trip ends at every
        // state sample: the window is kept sorted as it slides (a binary search and a shift of at
        // most 1024 durations), where selecting the percentiles from a copy of the window at
        // every new round trip was a tenth of a simulated campaign's time.
        if self.rtts.len() == RTT_WINDOW
            && let Some(oldest) = self.rtts.pop_front()
            && let Ok(at) = self.sorted.binary_search(&oldest)
        {
            self.sorted.remove(at);
        }
        self.rtts.push_back(rtt);
        let at = self.sorted.partition_point(|d| *d <= rtt);
        self.sorted.insert(at, rtt);
        self.figures.answered += 1;
    }

    pub(crate) fn snapshot(&mut self) -> LinkHealth {
        LinkHealth {
            rtt_p50: percentile(&self.sorted, 50),
            rtt_p99: percentile(&self.sorted, 99),
            silent_for: self.last_heard.map(|heard| heard.elapsed()),
            ..self.figures.clone()
        }
    }
}

/// The nearest-rank percentile `pct` (0..=100) of sorted samples: the value of rank
/// `⌈pct · n / 100⌉` (at least 1); `None` for none. The same definition as
/// `trajgen::stats::nearest_rank`, kept here because `car-link` depends on no other crate of the
/// workspace.
pub fn percentile(sorted: &[Duration], pct: usize) -> Option<Duration> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (pct * sorted.len()).div_ceil(100).clamp(1, sorted.len());
    sorted.get(rank - 1).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sliding_window_gives_the_percentiles_of_its_round_trips_sorted() {
        let mut noise = 12_345_u64;
        let mut recorder = HealthRecorder::default();
        let mut all = Vec::new();
        for n in 1..=3 * RTT_WINDOW {
            noise = noise
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            // Few distinct values: ties leave the window too.
            let rtt = Duration::from_micros(noise >> 58);
            recorder.record_rtt(rtt);
            all.push(rtt);
            if n % 97 == 0 || n == RTT_WINDOW || n == RTT_WINDOW + 1 {
                let mut window = all[all.len().saturating_sub(RTT_WINDOW)..].to_vec();
                window.sort_unstable();
                let health = recorder.snapshot();
                assert_eq!(health.rtt_p50, percentile(&window, 50), "{n}");
                assert_eq!(health.rtt_p99, percentile(&window, 99), "{n}");
                assert_eq!(recorder.sorted, window, "{n}");
            }
        }
    }

    #[test]
    fn nearest_rank_percentiles() {
        let samples: Vec<Duration> = (1..=100).map(Duration::from_millis).collect();
        assert_eq!(percentile(&samples, 50), Some(Duration::from_millis(50)));
        assert_eq!(percentile(&samples, 99), Some(Duration::from_millis(99)));
        assert_eq!(percentile(&[], 50), None);
        assert_eq!(
            percentile(&samples[..1], 99),
            Some(Duration::from_millis(1))
        );
    }

    #[test]
    fn the_window_keeps_the_latest_round_trips() {
        let mut recorder = HealthRecorder::default();
        for _ in 0..RTT_WINDOW {
            recorder.record_rtt(Duration::from_secs(1));
        }
        assert_eq!(recorder.snapshot().rtt_p50, Some(Duration::from_secs(1)));
        for _ in 0..RTT_WINDOW {
            recorder.record_rtt(Duration::from_millis(1));
        }
        let health = recorder.snapshot();
        assert_eq!(health.rtt_p99, Some(Duration::from_millis(1)));
        assert_eq!(health.answered, 2 * RTT_WINDOW as u64);
    }
}
