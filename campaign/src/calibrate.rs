//! Fitting a car profile to recordings of a car (`drivecheck calibrate`, `docs/twin.md`): the
//! policy, pure. The driving (a candidate profile's simulated runs of the recorded cases) is the
//! caller's, behind a function it hands to [`fit`].
//!
//! **What is compared.** Only what a car reports: the UWB − RTK error of its state samples. Each
//! judged segment of each test is cut into [`BINS`] equal stretches of time and the error vector
//! averaged in each: a [`Signature`]. A biased or displaced anchor, a wrong odometry scale or yaw
//! bias each move the error in their own direction at their own places along the route, so the
//! binned vectors (not only their size) tell them apart; averaging inside a bin removes most of
//! the noise. The misfit of a candidate is the mean over the bins both have of |recorded −
//! simulated|², the simulated bin the mean over the candidate's runs.
//!
//! **How it is fitted.** A pattern search (Hooke–Jeeves, with halving steps): each parameter in
//! turn is tried a step up and down, moved to the better side when the misfit falls and on in
//! that direction while it keeps falling; after a sweep that moved, the sweep's whole change is
//! tried once more (the pattern move, which follows a valley no single parameter runs along);
//! after a sweep that did not, the steps halve, until they are below their resolution or the
//! budget is spent.
//! It needs no gradient, tolerates the misfit's small roughness (the simulated runs use the same
//! seeds for every candidate, so the noise is common and the misfit changes smoothly with the
//! parameters), and its cost is known: at most two evaluations per parameter and sweep.
//!
//! **How sure.** At the optimum, each parameter's curvature `c` of the misfit (from the misfit a
//! step each side) gives its standard error `√(J / (n·c))` for `n` compared bins and misfit `J`,
//! the Gauss–Newton approximation for independent residuals (the residuals of one test are not
//! quite independent: read it as a scale, not a confidence interval). A parameter whose step
//! changes the misfit by less than [`IDENTIFIED_RELATIVE`] of it is *not identified*: the
//! recordings cannot tell its values apart (an anchor the car never ranged, say) and it keeps its
//! starting value.

use std::collections::BTreeMap;

/// Stretches of time each segment is cut into.
pub const BINS: usize = 4;

/// The least relative change of the misfit a parameter's step must make for the parameter to
/// count as identified.
pub const IDENTIFIED_RELATIVE: f64 = 0.01;

/// One state sample: seconds since the test began, the UWB − RTK error (east, north), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorSample {
    /// Seconds since the test began.
    pub t_s: f64,
    /// UWB − RTK, east, m.
    pub east_m: f64,
    /// UWB − RTK, north, m.
    pub north_m: f64,
}

/// A judged segment's time span, seconds since the test began.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentSpan {
    /// The segment's index.
    pub segment_index: usize,
    /// Its start.
    pub from_s: f64,
    /// Its end.
    pub to_s: f64,
}

/// The binned error of a set of tests: (test, segment, bin) → mean error (east, north), m.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Signature {
    /// The bins.
    pub bins: BTreeMap<(usize, usize, usize), (f64, f64)>,
}

impl Signature {
    /// Adds test `test_index`'s `samples` (finite ones), cut by its `segments`.
    pub fn add_test(
        &mut self,
        test_index: usize,
        samples: &[ErrorSample],
        segments: &[SegmentSpan],
    ) {
        for segment in segments {
            let length = segment.to_s - segment.from_s;
            if length.is_nan() || length <= 0.0 {
                continue;
            }
            let mut sums = [(0.0, 0.0, 0usize); BINS];
            for s in samples.iter().filter(|s| {
                s.east_m.is_finite()
                    && s.north_m.is_finite()
                    && (segment.from_s..segment.to_s).contains(&s.t_s)
            }) {
                let bin = (((s.t_s - segment.from_s) / length) * BINS as f64) as usize;
                let sum = &mut sums[bin.min(BINS - 1)];
                sum.0 += s.east_m;
                sum.1 += s.north_m;
                sum.2 += 1;
            }
            for (bin, (east, north, n)) in sums.into_iter().enumerate() {
                if n > 0 {
                    self.bins.insert(
                        (test_index, segment.segment_index, bin),
                        (east / n as f64, north / n as f64),
                    );
                }
            }
        }
    }

    /// The mean of `runs` bin by bin (a bin of some runs only: the mean of those).
    pub fn mean(runs: &[Signature]) -> Signature {
        let mut sums: BTreeMap<(usize, usize, usize), (f64, f64, usize)> = BTreeMap::new();
        for run in runs {
            for (&key, &(e, n)) in &run.bins {
                let sum = sums.entry(key).or_default();
                sum.0 += e;
                sum.1 += n;
                sum.2 += 1;
            }
        }
        Signature {
            bins: sums
                .into_iter()
                .map(|(k, (e, n, c))| (k, (e / c as f64, n / c as f64)))
                .collect(),
        }
    }
}

/// The misfit of `simulated` against `recorded`: the mean of |recorded − simulated|² over the bins
/// both have (m²) and their number; `None` when they share no bin.
pub fn misfit(recorded: &Signature, simulated: &Signature) -> Option<(f64, usize)> {
    let mut sum = 0.0;
    let mut n = 0;
    for (key, &(re, rn)) in &recorded.bins {
        if let Some(&(se, sn)) = simulated.bins.get(key) {
            sum += (re - se).powi(2) + (rn - sn).powi(2);
            n += 1;
        }
    }
    (n > 0).then(|| (sum / n as f64, n))
}

/// A parameter of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Its name, as the profile writes it (`anchors."50".offset_m[0]`).
    pub name: String,
    /// The starting value.
    pub start: f64,
    /// The first step.
    pub step: f64,
    /// The smallest step worth taking (its resolution).
    pub resolution: f64,
    /// The values it may take.
    pub bounds: (f64, f64),
}

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// Its name.
    pub name: String,
    /// Its fitted value (its starting value when not identified).
    pub value: f64,
    /// Its standard error (see the module doc), when identified.
    pub standard_error: Option<f64>,
    /// Whether the recordings tell its values apart.
    pub identified: bool,
}

/// What a fit found.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    /// Every parameter.
    pub parameters: Vec<Fitted>,
    /// The misfit of the starting values, m².
    pub start_misfit: f64,
    /// The misfit of the fitted values, m².
    pub misfit: f64,
    /// Bins compared.
    pub bins: usize,
    /// Evaluations made.
    pub evaluations: usize,
    /// Whether the budget ended the search before the steps reached their resolution.
    pub out_of_budget: bool,
}

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The starting values' runs share no bin with the recordings.
    #[error("the simulated runs and the recordings have no segment in common to compare")]
    NothingToCompare,
    /// Driving a candidate failed.
    #[error("{0}")]
    Driving(String),
}

/// Fits `parameters` so that `evaluate` (the misfit and bins compared of a candidate's values, or
/// an error) is least, while `in_budget` says there is time; then measures each parameter's
/// curvature. `progress` hears every evaluation's number and the best misfit so far.
pub fn fit(
    parameters: &[Parameter],
    mut evaluate: impl FnMut(&[f64]) -> Result<Option<(f64, usize)>, String>,
    mut in_budget: impl FnMut() -> bool,
    mut progress: impl FnMut(usize, f64),
) -> Result<Fit, FitError> {
    let mut evaluations = 0;
    let bins = std::cell::Cell::new(0usize);
    let mut eval = |values: &[f64], evaluations: &mut usize| -> Result<f64, FitError> {
        *evaluations += 1;
        match evaluate(values).map_err(FitError::Driving)? {
            Some((j, n)) => {
                bins.set(bins.get().max(n));
                Ok(j)
            }
            None => Ok(f64::INFINITY),
        }
    };
    let mut values: Vec<f64> = parameters.iter().map(|p| p.start).collect();
    let start_misfit = eval(&values, &mut evaluations)?;
    if !start_misfit.is_finite() {
        return Err(FitError::NothingToCompare);
    }
    let mut best = start_misfit;
    let mut steps: Vec<f64> = parameters.iter().map(|p| p.step).collect();
    let mut out_of_budget = false;
    'search: loop {
        let before = values.clone();
        let mut moved = false;
        for (i, p) in parameters.iter().enumerate() {
            if steps[i] < p.resolution {
                continue;
            }
            // Both directions; the better one, followed while it keeps improving.
            let mut best_direction = None;
            for direction in [1.0, -1.0] {
                if !in_budget() {
                    out_of_budget = true;
                    break 'search;
                }
                let candidate = (values[i] + direction * steps[i]).clamp(p.bounds.0, p.bounds.1);
                if candidate == values[i] {
                    continue;
                }
                let mut trial = values.clone();
                trial[i] = candidate;
                let j = eval(&trial, &mut evaluations)?;
                progress(evaluations, best.min(j));
                if j < best {
                    best = j;
                    best_direction = Some((direction, trial));
                }
            }
            let Some((direction, trial)) = best_direction else {
                continue;
            };
            values = trial;
            moved = true;
            loop {
                if !in_budget() {
                    out_of_budget = true;
                    break 'search;
                }
                let candidate = (values[i] + direction * steps[i]).clamp(p.bounds.0, p.bounds.1);
                if candidate == values[i] {
                    break;
                }
                let mut trial = values.clone();
                trial[i] = candidate;
                let j = eval(&trial, &mut evaluations)?;
                progress(evaluations, best.min(j));
                if j >= best {
                    break;
                }
                best = j;
                values = trial;
            }
        }
        if moved {
            // The pattern move: the sweep's whole change once more.
            if !in_budget() {
                out_of_budget = true;
                break;
            }
            let trial: Vec<f64> = parameters
                .iter()
                .enumerate()
                .map(|(i, p)| (2.0 * values[i] - before[i]).clamp(p.bounds.0, p.bounds.1))
                .collect();
            let j = eval(&trial, &mut evaluations)?;
            progress(evaluations, best.min(j));
            if j < best {
                best = j;
                values = trial;
            }
            continue;
        }
        let mut any = false;
        for (i, p) in parameters.iter().enumerate() {
            if steps[i] >= p.resolution {
                steps[i] /= 2.0;
                any |= steps[i] >= p.resolution;
            }
        }
        if !any {
            break;
        }
    }
    // Curvature at the optimum, a resolution-sized step each side (within bounds).
    let mut fitted = Vec::new();
    for (i, p) in parameters.iter().enumerate() {
        // A quarter of the first step: wide enough to see past the misfit's roughness.
        let h = p.resolution.max(p.step / 4.0);
        let mut up = values.clone();
        up[i] = (values[i] + h).min(p.bounds.1);
        let mut down = values.clone();
        down[i] = (values[i] - h).max(p.bounds.0);
        let (ju, jd) = (eval(&up, &mut evaluations)?, eval(&down, &mut evaluations)?);
        let (hu, hd) = (up[i] - values[i], values[i] - down[i]);
        let change = (ju - best).abs().max((jd - best).abs());
        let identified = change > IDENTIFIED_RELATIVE * best.max(1e-12);
        let curvature = if hu > 0.0 && hd > 0.0 {
            2.0 * (hu * (jd - best) + hd * (ju - best)) / (hu * hd * (hu + hd))
        } else {
            0.0
        };
        let standard_error = (identified && curvature > 0.0)
            .then(|| (best / (bins.get() as f64 * curvature)).sqrt());
        fitted.push(Fitted {
            name: p.name.clone(),
            value: if identified { values[i] } else { p.start },
            standard_error,
            identified,
        });
    }
    Ok(Fit {
        parameters: fitted,
        start_misfit,
        misfit: best,
        bins: bins.get(),
        evaluations,
        out_of_budget,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(f: impl Fn(f64) -> (f64, f64)) -> Vec<ErrorSample> {
        (0..100)
            .map(|k| {
                let t = f64::from(k) * 0.1;
                let (east_m, north_m) = f(t);
                ErrorSample {
                    t_s: t,
                    east_m,
                    north_m,
                }
            })
            .collect()
    }

    #[test]
    fn a_signature_averages_each_quarter_of_each_segment() {
        let mut s = Signature::default();
        let span = SegmentSpan {
            segment_index: 2,
            from_s: 0.0,
            to_s: 8.0,
        };
        s.add_test(5, &samples(|t| (t, -1.0)), &[span]);
        assert_eq!(s.bins.len(), BINS);
        // The first quarter holds t = 0.0 … 1.9: mean 0.95.
        let (e, n) = s.bins[&(5, 2, 0)];
        assert!(
            (e - 0.95).abs() < 1e-9 && (n + 1.0).abs() < 1e-12,
            "{e} {n}"
        );
        let recorded = s.clone();
        let mut shifted = Signature::default();
        shifted.add_test(5, &samples(|t| (t + 0.1, -1.0)), &[span]);
        let (j, bins) = misfit(&recorded, &shifted).unwrap();
        assert_eq!(bins, 4);
        assert!((j - 0.01).abs() < 1e-9, "{j}");
    }

    #[test]
    fn the_search_finds_a_quadratic_minimum_and_names_an_unidentified_parameter() {
        // Misfit (a − 0.3)² + 4 (b + 0.1)² + 0.01; c does nothing.
        let parameters = [("a", 0.0), ("b", 0.0), ("c", 0.5)].map(|(name, start)| Parameter {
            name: name.to_owned(),
            start,
            step: 0.4,
            resolution: 0.005,
            bounds: (-2.0, 2.0),
        });
        let fit = fit(
            &parameters,
            |v| {
                Ok(Some((
                    (v[0] - 0.3).powi(2) + 4.0 * (v[1] + 0.1).powi(2) + 0.01,
                    100,
                )))
            },
            || true,
            |_, _| {},
        )
        .unwrap();
        let [a, b, c] = &fit.parameters[..] else {
            panic!()
        };
        assert!((a.value - 0.3).abs() < 0.01, "{a:?}");
        assert!((b.value + 0.1).abs() < 0.01, "{b:?}");
        assert!(a.identified && b.identified && !c.identified);
        assert_eq!(c.value, 0.5, "an unidentified parameter keeps its start");
        // J ≈ 0.01, n = 100, curvature 2 and 8: standard errors 0.007 and 0.0035.
        assert!(
            (a.standard_error.unwrap() - (0.01f64 / 200.0).sqrt()).abs() < 0.002,
            "{a:?}"
        );
        assert!(b.standard_error.unwrap() < a.standard_error.unwrap());
        assert!(fit.misfit < fit.start_misfit && !fit.out_of_budget);
    }

    #[test]
    fn the_budget_ends_the_search_with_the_best_so_far() {
        let parameters = [Parameter {
            name: "a".to_owned(),
            start: 0.0,
            step: 0.1,
            resolution: 1e-6,
            bounds: (-5.0, 5.0),
        }];
        let mut calls = 0;
        let fit = fit(
            &parameters,
            |v| Ok(Some(((v[0] - 3.0).powi(2), 10))),
            || {
                calls += 1;
                calls < 5
            },
            |_, _| {},
        )
        .unwrap();
        assert!(fit.out_of_budget);
        assert!(fit.misfit < fit.start_misfit);
    }
}
