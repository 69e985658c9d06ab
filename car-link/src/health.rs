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
    /// Candidate frames dropped by the decoder (bad CRC, end byte, length, abandoned).
    pub dropped_frames: u64,
    /// Valid frames whose payload did not decode.
    pub undecodable: u64,
    /// Time since the car last sent a valid frame (`None` before the first). Over UDP, or a TCP connection
    /// whose far end vanished without closing it, a dead car shows here and in the timeouts, since no
    /// connection closes to report it lost.
    pub silent_for: Option<Duration>,
}

/// Accumulates health figures; snapshots are taken with [`HealthRecorder::snapshot`].
#[derive(Debug, Default)]
pub(crate) struct HealthRecorder {
    rtts: VecDeque<Duration>,
    pub(crate) figures: LinkHealth,
    /// When the car last sent a valid frame.
    pub(crate) last_heard: Option<Instant>,
    /// The round-trip percentiles (p50, p99) of `rtts`, until the next round trip.
    percentiles: Option<(Option<Duration>, Option<Duration>)>,
}

impl HealthRecorder {
    pub(crate) fn record_rtt(&mut self, rtt: Duration) {
        if self.rtts.len() == RTT_WINDOW {
            self.rtts.pop_front();
        }
        self.rtts.push_back(rtt);
        self.percentiles = None;
        self.figures.answered += 1;
    }

    pub(crate) fn snapshot(&mut self) -> LinkHealth {
        // A runner asks for a snapshot at every turn of its loop, far more often than a round
        // trip ends: the percentiles are computed once per new round trip (sorting the window at
        // every snapshot was a sixth of a simulated campaign's time).
        let rtts = &self.rtts;
        let (rtt_p50, rtt_p99) = *self.percentiles.get_or_insert_with(|| {
            let mut rtts: Vec<Duration> = rtts.iter().copied().collect();
            (select(&mut rtts, 50), select(&mut rtts, 99))
        });
        LinkHealth {
            rtt_p50,
            rtt_p99,
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

/// [`percentile`] of unsorted samples (reordered in place), in linear time.
fn select(samples: &mut [Duration], pct: usize) -> Option<Duration> {
    if samples.is_empty() {
        return None;
    }
    let rank = (pct * samples.len()).div_ceil(100).clamp(1, samples.len());
    Some(*samples.select_nth_unstable(rank - 1).1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selected_percentiles_are_the_sorted_ones() {
        let mut noise = 12_345_u64;
        let mut samples: Vec<Duration> = (0..777)
            .map(|_| {
                noise = noise
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1);
                Duration::from_micros(noise >> 52)
            })
            .collect();
        let mut sorted = samples.clone();
        sorted.sort_unstable();
        for pct in [0, 1, 50, 99, 100] {
            assert_eq!(select(&mut samples, pct), percentile(&sorted, pct), "{pct}");
        }
        assert_eq!(select(&mut [], 50), None);
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
