//! `drivecheck-dev bench fidelity`'s route following (`docs/fidelity.md#route-following`): the
//! published circle route driven by the simulated car, next to the real car's recordings of it.
//!
//! The real car's data is in the firmware's public repository, vedderb/rise_sdvp at commit
//! 8b9c36a0003023ef53d7f8d0e5fb2c0728fa609a, `Misc/Test Data/paper_2018-06/`: the route
//! (`routes/route_circle.xml`, its second route: a circle of radius 10 m at 4 km/h) and two
//! recordings of the car driving it (`plot_data/diff_circle.xml` and `plot_data/ap_circle.xml`,
//! their "Diff (cm)" graphs). They are bundled in `devtools/data/real-car/` and summarised by
//! the same code as the simulated printouts ([`Figures::of`]).

use anyhow::{Context, Result, bail};
use car_sim::route_following::{self, Printouts, RouteDrive};
use car_sim::{CarOptions, GnssModel, RoutePoint};

/// The real car at each RTK fix: the fused position history's point closest to the fix time to
/// the fix, cm, one per fix (5 Hz).
const REAL_GNSS_DIFF: &str = include_str!("../../data/real-car/circle-gnss-diff.csv");
/// The real car's distance to the route, cm, every 10th autopilot iteration.
const REAL_ROUTE_DISTANCE: &str = include_str!("../../data/real-car/circle-route-distance.csv");
/// The circle route: x, y (m), speed (m/s).
const CIRCLE_ROUTE: &str = include_str!("../../data/real-car/circle-route.csv");

/// The firmware's autopilot rate (`autopilot.c`, `AP_HZ`): an iteration every 10 ms.
const AP_ITERATION_S: f64 = 0.01;
/// `ap_print_closest 10`: the real recording printed every 10th iteration (its sample numbers
/// step by 10).
const PRINT_EVERY: u32 = 10;
/// Simulated driving before recording: the simulated fused estimate starts exact, the real
/// recordings start mid-drive.
const WARM_UP_MS: u64 = 20_000;

/// The summary of one drive's printouts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// The history point closest to each fix's time to the fix: median, cm.
    pub gnss_diff_p50_cm: f64,
    /// The same, 95th percentile, cm.
    pub gnss_diff_p95_cm: f64,
    /// The distance to the route: median, cm.
    pub route_p50_cm: f64,
    /// The same, 95th percentile, cm.
    pub route_p95_cm: f64,
    /// The mean absolute change of the distance to the route between consecutive prints (100 ms
    /// apart), cm.
    pub route_change_cm: f64,
    /// The distance to the route's correlation time, s: `−Δt / ln ρ₁`, with ρ₁ the lag-one
    /// autocorrelation of the series (its mean removed) and Δt = 100 ms, the correlation time of
    /// a first-order Gauss–Markov process with that ρ₁ (0 when ρ₁ ≤ 0).
    pub route_correlation_s: f64,
}

impl Figures {
    /// The figures of a drive: the fix differences (cm) and the route distances (cm, `period_s`
    /// apart).
    pub fn of(gnss_diff_cm: &[f64], route_distance_cm: &[f64], period_s: f64) -> Self {
        Self {
            gnss_diff_p50_cm: percentile(gnss_diff_cm, 0.5),
            gnss_diff_p95_cm: percentile(gnss_diff_cm, 0.95),
            route_p50_cm: percentile(route_distance_cm, 0.5),
            route_p95_cm: percentile(route_distance_cm, 0.95),
            route_change_cm: mean_abs_change(route_distance_cm),
            route_correlation_s: correlation_time(route_distance_cm, period_s),
        }
    }

    /// The figures in the order of the table's rows.
    fn rows(&self) -> [f64; 6] {
        [
            self.gnss_diff_p50_cm,
            self.gnss_diff_p95_cm,
            self.route_p50_cm,
            self.route_p95_cm,
            self.route_change_cm,
            self.route_correlation_s,
        ]
    }
}

/// The table's rows: name and decimals.
const ROWS: [(&str, usize); 6] = [
    ("GNSS fix vs fused history p50 (cm)", 2),
    ("GNSS fix vs fused history p95 (cm)", 2),
    ("distance to the route p50 (cm)", 2),
    ("distance to the route p95 (cm)", 2),
    ("change of the distance per 100 ms, mean (cm)", 2),
    ("correlation time of the distance (s)", 2),
];

/// Nearest-rank percentile `q` of `values` (NaN for none).
fn percentile(values: &[f64], q: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    trajgen::stats::nearest_rank(&sorted, q).unwrap_or(f64::NAN)
}

/// The mean absolute difference between consecutive values (NaN for fewer than two).
fn mean_abs_change(values: &[f64]) -> f64 {
    let changes: Vec<f64> = values.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    if changes.is_empty() {
        return f64::NAN;
    }
    changes.iter().sum::<f64>() / changes.len() as f64
}

/// `−period_s / ln ρ₁`, ρ₁ the lag-one autocorrelation of `values` (0 when ρ₁ ≤ 0, NaN for
/// fewer than two values or a constant series).
fn correlation_time(values: &[f64], period_s: f64) -> f64 {
    if values.len() < 2 {
        return f64::NAN;
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let d: Vec<f64> = values.iter().map(|v| v - mean).collect();
    let c0: f64 = d.iter().map(|x| x * x).sum();
    let c1: f64 = d.windows(2).map(|w| w[0] * w[1]).sum();
    let rho = c1 / c0;
    if !rho.is_finite() {
        return f64::NAN;
    }
    if rho <= 0.0 {
        return 0.0;
    }
    -period_s / rho.ln()
}

/// The data rows of a bundled CSV (comments and the header line skipped), each split on commas.
fn csv_rows(text: &str) -> impl Iterator<Item = Vec<&str>> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .skip(1)
        .map(|l| l.split(',').map(str::trim).collect())
}

/// Column `column` of a bundled CSV as numbers.
fn column(text: &str, column: usize) -> Result<Vec<f64>> {
    csv_rows(text)
        .map(|row| {
            row.get(column)
                .context("a short row")?
                .parse::<f64>()
                .context("not a number")
        })
        .collect()
}

/// The real car's recordings: the fix differences and the route distances, cm.
fn real_series() -> Result<(Vec<f64>, Vec<f64>)> {
    let diff = column(REAL_GNSS_DIFF, 1).context("circle-gnss-diff.csv")?;
    let route = column(REAL_ROUTE_DISTANCE, 1).context("circle-route-distance.csv")?;
    Ok((diff, route))
}

/// The real car's figures, from the bundled recordings.
pub fn real() -> Result<Figures> {
    let (diff, route) = real_series()?;
    Ok(Figures::of(
        &diff,
        &route,
        f64::from(PRINT_EVERY) * AP_ITERATION_S,
    ))
}

/// The published circle route.
fn circle_route() -> Result<Vec<RoutePoint>> {
    csv_rows(CIRCLE_ROUTE)
        .map(|row| {
            let [x, y, speed] = row[..] else {
                bail!("circle-route.csv: a row without x, y and speed");
            };
            Ok(RoutePoint::at(x.parse()?, y.parse()?, speed.parse()?))
        })
        .collect()
}

/// The simulated car (the default car with `gnss`, seeded `seed`) driving the circle route for as
/// many fixes and prints as the real recordings hold: its figures.
pub fn simulated(base: &CarOptions, gnss: GnssModel, seed: u64) -> Result<Figures> {
    let (diff, route) = real_series()?;
    let printouts = route_following::drive(&RouteDrive {
        options: CarOptions {
            seed,
            gnss,
            ..base.clone()
        },
        route: circle_route()?,
        warm_up_ms: WARM_UP_MS,
        corrections: diff.len(),
        prints: route.len(),
        print_every: PRINT_EVERY,
    })?;
    let Printouts {
        gnss_diff_m,
        route_distance_m,
    } = printouts;
    let cm = |v: Vec<f64>| v.into_iter().map(|m| m * 100.0).collect::<Vec<_>>();
    Ok(Figures::of(
        &cm(gnss_diff_m),
        &cm(route_distance_m),
        f64::from(PRINT_EVERY) * AP_ITERATION_S,
    ))
}

/// The simulated figures for each seed.
pub fn simulated_runs(base: &CarOptions, gnss: GnssModel, seeds: &[u64]) -> Result<Vec<Figures>> {
    seeds
        .iter()
        .map(|&seed| simulated(base, gnss, seed))
        .collect()
}

/// The median of the runs' figure `row` and their range.
fn summary(runs: &[Figures], row: usize, decimals: usize) -> String {
    let values: Vec<f64> = runs.iter().map(|f| f.rows()[row]).collect();
    let (lo, hi) = values
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    format!(
        "{:.decimals$} ({lo:.decimals$}–{hi:.decimals$})",
        percentile(&values, 0.5)
    )
}

/// Prints the comparison: the real car and the simulated runs (seeded `seeds`).
pub fn print(base: &CarOptions, seeds: &[u64]) -> Result<()> {
    let gnss = base.gnss;
    let real = real()?;
    let runs = simulated_runs(base, gnss, seeds)?;
    println!(
        "## Route following on the published circle route: the real car and {} simulated runs\n",
        runs.len()
    );
    println!(
        "real car: vedderb/rise_sdvp 8b9c36a, `Misc/Test Data/paper_2018-06/` (diff_circle, ap_circle); \
         simulated GNSS: σ {:.2} cm per axis, correlation time {:.2} s\n",
        gnss.sigma_m * 100.0,
        gnss.correlation_s
    );
    println!("| | real car | simulated p50 (min–max) |\n|---|---|---|");
    for (row, (name, decimals)) in ROWS.iter().enumerate() {
        println!(
            "| {name} | {:.decimals$} | {} |",
            real.rows()[row],
            summary(&runs, row, *decimals)
        );
    }
    println!();
    Ok(())
}

/// The fit of the GNSS noise: every (σ, correlation time) of a grid, each with its simulated
/// figures' median over `seeds` and the misfit (the sum over the six figures of the squared log
/// ratio to the real car's), best last.
pub fn fit(seeds: &[u64]) -> Result<()> {
    let real = real()?;
    // σ 0.6–2.0 cm by 0.1; correlation time white, 0.1–1.0 s by 0.1, then coarser.
    let sigmas_cm = (6..=20).map(|k| f64::from(k) / 10.0);
    let correlations_s = (0..=10)
        .map(|k| f64::from(k) / 10.0)
        .chain([1.5, 2.0, 3.0, 5.0]);
    let mut results = Vec::new();
    for sigma_cm in sigmas_cm {
        for correlation_s in correlations_s.clone() {
            let gnss = GnssModel {
                sigma_m: sigma_cm / 100.0,
                correlation_s,
                ..GnssModel::default()
            };
            let runs = simulated_runs(&CarOptions::default(), gnss, seeds)?;
            let medians: Vec<f64> = (0..ROWS.len())
                .map(|row| percentile(&runs.iter().map(|f| f.rows()[row]).collect::<Vec<_>>(), 0.5))
                .collect();
            let misfit: f64 = medians
                .iter()
                .zip(real.rows())
                .map(|(sim, real)| (sim / real).ln().powi(2))
                .sum();
            results.push((misfit, sigma_cm, correlation_s, medians));
        }
    }
    results.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!(
        "| σ (cm) | correlation (s) | misfit | {} |",
        ROWS.map(|r| r.0).join(" | ")
    );
    println!("|---|---|---|{}", "---|".repeat(ROWS.len()));
    println!(
        "| real car | | | {} |",
        real.rows().map(|v| format!("{v:.2}")).join(" | ")
    );
    for (misfit, sigma_cm, correlation_s, medians) in results {
        let cells: Vec<String> = medians.iter().map(|v| format!("{v:.2}")).collect();
        println!(
            "| {sigma_cm:.1} | {correlation_s:.1} | {misfit:.3} | {} |",
            cells.join(" | ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_recordings_are_whole() {
        let (diff, route) = real_series().unwrap();
        assert_eq!((diff.len(), route.len()), (792, 950));
        assert_eq!(circle_route().unwrap().len(), 73);
    }

    #[test]
    fn a_first_order_gauss_markov_series_gives_back_its_correlation_time() {
        let a = (-0.1f64 / 0.6).exp();
        let mut state: u64 = 7;
        let mut uniform = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut e = 0.0;
        let values: Vec<f64> = (0..200_000)
            .map(|_| {
                e = a * e + uniform();
                e
            })
            .collect();
        let tau = correlation_time(&values, 0.1);
        assert!((tau - 0.6).abs() < 0.03, "{tau}");
        assert_eq!(correlation_time(&[1.0, -1.0, 1.0, -1.0], 0.1), 0.0);
        assert!(correlation_time(&[1.0], 0.1).is_nan());
    }

    #[test]
    fn the_change_is_the_mean_absolute_step() {
        assert_eq!(mean_abs_change(&[1.0, 2.0, 1.5, 1.5]), 0.5);
        assert!(mean_abs_change(&[1.0]).is_nan());
    }
}
