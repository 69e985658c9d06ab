//! Where a difference lives: the paired segments grouped by active fault, by commanded speed and
//! by region, a row per group.

use std::collections::BTreeMap;

use serde::Serialize;

use super::stats::median;
use super::{Options, Paired, PairedSegment};

/// One group of paired segments.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BreakdownRow {
    /// The group: `uwb_range_50 offset` (or `none`), `6–8 km/h`, `x 10–20 m, y 0–10 m`.
    pub key: String,
    /// Segments driven in both runs.
    pub segments: usize,
    /// The median change of their largest deviation (NEW − BASE), metres (`None` without a
    /// measured one).
    pub median_change_m: Option<f64>,
    /// Changed upwards by more than the noise.
    pub worse: usize,
    /// Downwards by more than the noise.
    pub better: usize,
    /// Segments BASE passed and NEW did not.
    pub regressed: usize,
    /// Segments NEW passed and BASE did not.
    pub fixed: usize,
}

impl BreakdownRow {
    /// How much of the regression the row holds: worse than the noise minus better, plus
    /// regressed minus fixed segment verdicts.
    pub fn regression_score(&self) -> i64 {
        self.worse as i64 - self.better as i64 + self.regressed as i64 - self.fixed as i64
    }
}

/// The breakdowns of a comparison, each sorted so the row that explains most of the regression
/// comes first: by how much its [`BreakdownRow::regression_score`] exceeds its segments' share of
/// the whole comparison's (the score of every paired segment, each counted once), then the larger
/// median change, then more segments, then the key. A row is blamed for what is peculiar to it,
/// not for its size: a fault that acted on many segments, beside the one whose segments all got
/// worse, does not come first for the share of them it was present at.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Breakdowns {
    /// By the probe and kind of each fault acting while the segment was driven (in either run; a
    /// segment with two faults is in both rows), `none` for a segment without one.
    pub by_fault: Vec<BreakdownRow>,
    /// By commanded speed, in bands of `speed_band_kmh`.
    pub by_speed: Vec<BreakdownRow>,
    /// By the square cell of side `region_cell_m` holding the middle of the segment's route.
    pub by_region: Vec<BreakdownRow>,
}

#[derive(Default)]
struct Group {
    segments: usize,
    changes: Vec<f64>,
    worse: usize,
    better: usize,
    regressed: usize,
    fixed: usize,
}

impl Breakdowns {
    /// The breakdowns of `paired` with `options`' noise, band and cell.
    pub fn of(paired: &Paired, options: &Options) -> Self {
        let band = options.speed_band_kmh;
        let cell = options.region_cell_m;
        Self {
            by_fault: rows(paired, options.noise_m, |s| {
                if s.faults.is_empty() {
                    vec!["none".to_owned()]
                } else {
                    s.faults.iter().map(ToString::to_string).collect()
                }
            }),
            by_speed: rows(paired, options.noise_m, |s| {
                vec![match s.speed_mps {
                    Some(v) if v.is_finite() => {
                        let k = (v * 3.6 / band).floor();
                        format!("{}–{} km/h", trim(k * band), trim((k + 1.0) * band))
                    }
                    _ => "unknown speed".to_owned(),
                }]
            }),
            by_region: rows(paired, options.noise_m, |s| {
                vec![match s.midpoint() {
                    Some([x, y]) if x.is_finite() && y.is_finite() => {
                        let (i, j) = ((x / cell).floor(), (y / cell).floor());
                        format!(
                            "x {}–{} m, y {}–{} m",
                            trim(i * cell),
                            trim((i + 1.0) * cell),
                            trim(j * cell),
                            trim((j + 1.0) * cell)
                        )
                    }
                    _ => "unknown place".to_owned(),
                }]
            }),
        }
    }
}

/// A number without a needless fraction (`10`, `2.5`), and `0` for −0.
fn trim(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let text = format!("{v:.3}");
    text.trim_end_matches('0').trim_end_matches('.').to_owned()
}

fn rows(
    paired: &Paired,
    noise: f64,
    keys: impl Fn(&PairedSegment) -> Vec<String>,
) -> Vec<BreakdownRow> {
    let mut groups: BTreeMap<String, Group> = BTreeMap::new();
    // The whole comparison's regression score and its segments, each segment once.
    let (mut total_score, mut total_segments) = (0i64, 0usize);
    for s in paired.segments() {
        let change = s.change_m();
        total_segments += 1;
        total_score += i64::from(s.regressed()) - i64::from(s.fixed())
            + change.map_or(0, |c| i64::from(c > noise) - i64::from(c < -noise));
        for key in keys(s) {
            let g = groups.entry(key).or_default();
            g.segments += 1;
            g.regressed += usize::from(s.regressed());
            g.fixed += usize::from(s.fixed());
            if let Some(c) = change {
                g.changes.push(c);
                g.worse += usize::from(c > noise);
                g.better += usize::from(c < -noise);
            }
        }
    }
    let mut rows: Vec<BreakdownRow> = groups
        .into_iter()
        .map(|(key, g)| BreakdownRow {
            key,
            segments: g.segments,
            median_change_m: median(&g.changes),
            worse: g.worse,
            better: g.better,
            regressed: g.regressed,
            fixed: g.fixed,
        })
        .collect();
    let per_segment = if total_segments == 0 {
        0.0
    } else {
        total_score as f64 / total_segments as f64
    };
    let excess = |r: &BreakdownRow| r.regression_score() as f64 - r.segments as f64 * per_segment;
    rows.sort_by(|a, b| {
        excess(b)
            .total_cmp(&excess(a))
            .then_with(|| {
                let m = |r: &BreakdownRow| r.median_change_m.unwrap_or(f64::NEG_INFINITY);
                m(b).total_cmp(&m(a))
            })
            .then_with(|| b.segments.cmp(&a.segments))
            .then_with(|| a.key.cmp(&b.key))
    });
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_keys_are_short() {
        assert_eq!(trim(10.0), "10");
        assert_eq!(trim(-0.0), "0");
        assert_eq!(trim(2.5), "2.5");
        assert_eq!(trim(-20.0), "-20");
    }
}
