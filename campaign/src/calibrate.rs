//! Fitting a car profile to recordings of a car (`drivecheck calibrate`, `docs/twin.md`): the
//! policy, pure. The driving (a candidate profile's simulated runs of the recorded cases) is the
//! caller's, behind a function it hands to [`fit`], which may drive a batch of candidates at once.
//!
//! **What is compared.** Only what a car reports: the UWB − RTK error of its state samples. Each
//! judged segment of each test is cut into [`BINS`] equal stretches of time and the error vector
//! averaged in each: a [`Signature`]. A biased or displaced anchor, a wrong odometry scale or yaw
//! bias each move the error in their own direction at their own places along the route, so the
//! binned vectors (not only their size) tell them apart; averaging inside a bin removes most of
//! the noise. The residuals of a candidate are recorded − simulated, east and north, for every
//! bin both have; its misfit is the mean over those bins of |recorded − simulated|².
//!
//! **How it is fitted.** Levenberg–Marquardt on those residuals: the effect of each parameter is
//! measured by moving it one [`Parameter::step`] (a batch of one candidate per parameter, which
//! the caller may drive in parallel), the Gauss–Newton step of that Jacobian is tried with two
//! dampings at once (a second batch), the better is kept when it lowers the misfit, and the
//! damping grows when neither does. The simulated runs use the same seeds for every candidate, so
//! their noise is common and the residuals change smoothly with the parameters; the step is wide
//! enough to see past what roughness is left. It needs a handful of iterations of `parameters +
//! 2` candidates, where a search one parameter at a time needs hundreds, and its Jacobian is what
//! says how sure the fit is. A descent finds the valley it starts in; the misfit of a car can
//! have more than one (an odometry scale too large and anchors moved to match fit as well as
//! the truth), so the fit descends again from restarts, [`RESTART_TOLERANCES`] tolerances away
//! in patterns of directions, while the budget lasts. Of the descents whose misfit is within
//! [`AS_GOOD`] of the lowest, it keeps the one that changes the starting profile least (in
//! tolerances): the recordings cannot choose between them, and the lowest of them mostly fits
//! the simulated runs' noise.
//!
//! **How sure.** At the optimum, with the Jacobian `J` and `A = JᵀJ`, the covariance of the
//! parameters is the sandwich `A⁻¹ (Σₜ gₜ gₜᵀ) A⁻¹` over the tests t, `gₜ = Jₜᵀ rₜ` of test t's
//! residuals: the bins of one test share its errors (the same anchors in the same places, the
//! same GNSS drift), so they count as one cluster, not as independent residuals. Each
//! parameter's standard error is the larger of that and `s² A⁻¹`'s (independent residuals: too
//! small alone, but it sees a direction the recordings say nothing of, where the sandwich is
//! blind); read it as a scale, not a confidence interval. The correlations are `A⁻¹`'s, the
//! design's: two parameters whose correlation is beyond [`TRADE_OFF`] *trade off* (moving an
//! anchor away from where the car drives looks like a longer range), and the recordings fix only
//! their combination. A parameter whose standard error is larger than its
//! [`Parameter::tolerance`] is *not identified*: the recordings cannot tell its values apart
//! (an anchor the car never ranged, or one half of a trade-off); so is one that another descent
//! put more than its tolerance away with a misfit as good (within [`AS_GOOD`]): the curvature of
//! one valley cannot see another.

use std::collections::BTreeMap;

/// Stretches of time each segment is cut into.
pub const BINS: usize = 4;

/// The correlation beyond which two fitted parameters are said to trade off.
pub const TRADE_OFF: f64 = 0.9;

/// Iterations of the fit at most (each `parameters + 2` candidates).
pub const MAX_ITERATIONS: usize = 20;

/// How far a restart starts from the starting values, in tolerances of each parameter.
pub const RESTART_TOLERANCES: f64 = 3.0;

/// How much larger than the best a restart's misfit (an rms, m) may be and still count as a fit
/// as good, relative: on the three cars of `docs/twin.md` the true profile's own misfit was up
/// to 7 % above the best fit's (a fit also fits the simulated runs' noise), so a smaller gap says
/// nothing of which is the car.
pub const AS_GOOD: f64 = 0.10;

/// The relative fall of the misfit below which an iteration counts as converged.
const CONVERGED_RELATIVE: f64 = 1e-3;
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

/// The [`SegmentSpan::segment_index`] of a test's start route: the stretch from the test's first
/// sample to its first segment, the same route from the same place in every test (where the
/// radio's noise and the anchors' offsets show without a fault or a segment's curvature).
pub const START_ROUTE: usize = usize::MAX;

/// One bin of a [`Signature`]: the mean error and how much it jumps from sample to sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bin {
    /// The mean error, east, m.
    pub east_m: f64,
    /// The mean error, north, m.
    pub north_m: f64,
    /// The root mean square of the error's change from one sample to the next, m (`None` with
    /// fewer than two samples): the radio's part of the error (its noise, the exchanges lost, the
    /// NLOS ranges), which a mean averages away and the car's slow errors (odometry, yaw) barely
    /// move.
    pub jitter_m: Option<f64>,
}

/// The binned error of a set of tests: (test, segment, bin) → its [`Bin`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Signature {
    /// The bins.
    pub bins: BTreeMap<(usize, usize, usize), Bin>,
}

impl Signature {
    /// Adds test `test_index`'s `samples` (finite ones, in time order), cut by its `segments`.
    pub fn add_test(
        &mut self,
        test_index: usize,
        samples: &[ErrorSample],
        segments: &[SegmentSpan],
    ) {
        #[derive(Default, Clone, Copy)]
        struct Sums {
            east: f64,
            north: f64,
            n: usize,
            jumps: f64,
            m: usize,
            last: Option<(f64, f64)>,
        }
        for segment in segments {
            let length = segment.to_s - segment.from_s;
            if length.is_nan() || length <= 0.0 {
                continue;
            }
            let mut sums = [Sums::default(); BINS];
            for s in samples.iter().filter(|s| {
                s.east_m.is_finite()
                    && s.north_m.is_finite()
                    && (segment.from_s..segment.to_s).contains(&s.t_s)
            }) {
                let bin = (((s.t_s - segment.from_s) / length) * BINS as f64) as usize;
                let sum = &mut sums[bin.min(BINS - 1)];
                sum.east += s.east_m;
                sum.north += s.north_m;
                sum.n += 1;
                if let Some((e, n)) = sum.last {
                    sum.jumps += (s.east_m - e).powi(2) + (s.north_m - n).powi(2);
                    sum.m += 1;
                }
                sum.last = Some((s.east_m, s.north_m));
            }
            for (bin, sum) in sums.into_iter().enumerate() {
                if sum.n > 0 {
                    self.bins.insert(
                        (test_index, segment.segment_index, bin),
                        Bin {
                            east_m: sum.east / sum.n as f64,
                            north_m: sum.north / sum.n as f64,
                            jitter_m: (sum.m > 0).then(|| (sum.jumps / sum.m as f64).sqrt()),
                        },
                    );
                }
            }
        }
    }

    /// The mean of `runs` bin by bin (a bin of some runs only: the mean of those; a jitter, of
    /// the runs that have one).
    pub fn mean(runs: &[Signature]) -> Signature {
        #[derive(Default)]
        struct Sums {
            east: f64,
            north: f64,
            n: usize,
            jitter: f64,
            m: usize,
        }
        let mut sums: BTreeMap<(usize, usize, usize), Sums> = BTreeMap::new();
        for run in runs {
            for (&key, bin) in &run.bins {
                let sum = sums.entry(key).or_default();
                sum.east += bin.east_m;
                sum.north += bin.north_m;
                sum.n += 1;
                if let Some(j) = bin.jitter_m {
                    sum.jitter += j;
                    sum.m += 1;
                }
            }
        }
        Signature {
            bins: sums
                .into_iter()
                .map(|(k, s)| {
                    (
                        k,
                        Bin {
                            east_m: s.east / s.n as f64,
                            north_m: s.north / s.n as f64,
                            jitter_m: (s.m > 0).then(|| s.jitter / s.m as f64),
                        },
                    )
                })
                .collect(),
        }
    }
}

/// A parameter of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Its name, as the profile writes it (`anchors."50".offset_m[0]`).
    pub name: String,
    /// The starting value.
    pub start: f64,
    /// How far it is moved to measure its effect: wide enough to see past the misfit's roughness,
    /// small against the values it may take.
    pub step: f64,
    /// The precision worth knowing it to: a larger standard error is *not identified*.
    pub tolerance: f64,
    /// The values it may take.
    pub bounds: (f64, f64),
}

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// Its name.
    pub name: String,
    /// Its fitted value.
    pub value: f64,
    /// Its standard error (see the module doc); `None` when the recordings say nothing of it.
    pub standard_error: Option<f64>,
    /// The parameter's tolerance ([`Parameter::tolerance`]).
    pub tolerance: f64,
    /// Whether the standard error is within the parameter's tolerance and no other fit as good
    /// put it elsewhere.
    pub identified: bool,
    /// The parameter it trades off with most and their correlation, beyond [`TRADE_OFF`].
    pub trades_off_with: Option<(String, f64)>,
    /// Where another fit as good (a restart's, within [`AS_GOOD`] of the best rms misfit) put it,
    /// when that is more than its tolerance away.
    pub also: Option<f64>,
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
    /// Candidates evaluated.
    pub evaluations: usize,
    /// Iterations made, over every descent.
    pub iterations: usize,
    /// Descents made: from the starting values and from restarts.
    pub fits: usize,
    /// Whether the budget ended the search before it converged.
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
    /// The caller's batch did not hold one signature per candidate.
    #[error("{given} signatures for {asked} candidates")]
    Batch {
        /// Candidates asked for.
        asked: usize,
        /// Signatures given.
        given: usize,
    },
}

/// What of the bins a fit compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compared {
    /// The judged segments' mean errors, east and north (not the start route's: every test
    /// starts it from a car just reset, whose error is mostly that reset's, 0.17 m rms between
    /// a car and its own replays on `drivecheck-dev bench twin-reach`'s car F). What the anchors,
    /// the odometry and the IMU shape.
    Means,
    /// Every bin's jitter, the start route's too: what the radio's noise and losses shape. Not
    /// the means: with the same seeds for every candidate a quieter radio makes quieter
    /// simulated means, which a least-squares fit of means prefers whatever the car (its
    /// expected misfit is the recorded noise plus the simulated), so a noise fitted on means
    /// comes out low.
    Jitter,
}

impl Compared {
    /// Residuals per bin.
    fn per_bin(self) -> usize {
        match self {
            Compared::Means => 2,
            Compared::Jitter => 1,
        }
    }
}

/// The residuals of candidates against the recording, over the bins the starting values' runs
/// share with it (a bin a later candidate lacks keeps the starting values' simulated bin: the
/// residual vector keeps its length and meaning).
struct Residuals<'a> {
    recorded: &'a Signature,
    compared: Compared,
    keys: Vec<(usize, usize, usize)>,
    fallback: Vec<Bin>,
}

impl<'a> Residuals<'a> {
    fn new(recorded: &'a Signature, start: &Signature, compared: Compared) -> Self {
        let (keys, fallback) = recorded
            .bins
            .iter()
            .filter_map(|(key, bin)| {
                let simulated = start.bins.get(key)?;
                let wanted = match compared {
                    Compared::Means => key.1 != START_ROUTE,
                    Compared::Jitter => bin.jitter_m.is_some() && simulated.jitter_m.is_some(),
                };
                wanted.then_some((*key, *simulated))
            })
            .unzip();
        Self {
            recorded,
            compared,
            keys,
            fallback,
        }
    }

    /// recorded − simulated of every bin: east and north, or the jitter (a jitter the candidate
    /// lacks is the starting values').
    fn of(&self, simulated: &Signature) -> Vec<f64> {
        let mut r = Vec::with_capacity(self.compared.per_bin() * self.keys.len());
        for (key, fallback) in self.keys.iter().zip(&self.fallback) {
            let recorded = self.recorded.bins[key];
            let simulated = simulated.bins.get(key).unwrap_or(fallback);
            match self.compared {
                Compared::Means => {
                    r.push(recorded.east_m - simulated.east_m);
                    r.push(recorded.north_m - simulated.north_m);
                }
                Compared::Jitter => r.push(
                    recorded.jitter_m.unwrap_or_default()
                        - simulated.jitter_m.or(fallback.jitter_m).unwrap_or_default(),
                ),
            }
        }
        r
    }

    /// The misfit of residuals `r`: the mean over the bins of their residuals' squares, m².
    fn misfit(&self, r: &[f64]) -> f64 {
        r.iter().map(|x| x * x).sum::<f64>() / self.keys.len() as f64
    }
}

/// Fits `parameters` so that the residuals of the signatures `evaluate` gives (one per candidate
/// of a batch, the candidates' values in `parameters`' order) against `recorded` are least, while
/// `in_budget` says there is time (see the module doc): from the starting values, then from
/// `restarts` other places while the budget lasts; then measures how sure each parameter is.
/// `progress` hears the number of candidates evaluated and the best misfit so far.
pub fn fit(
    parameters: &[Parameter],
    (recorded, compared): (&Signature, Compared),
    restarts: usize,
    mut evaluate: impl FnMut(&[Vec<f64>]) -> Result<Vec<Signature>, String>,
    mut in_budget: impl FnMut() -> bool,
    mut progress: impl FnMut(usize, f64),
) -> Result<Fit, FitError> {
    let mut evaluations = 0;
    let best_so_far = std::cell::Cell::new(f64::INFINITY);
    let mut batch = |candidates: &[Vec<f64>]| {
        let signatures = evaluate(candidates).map_err(FitError::Driving)?;
        if signatures.len() != candidates.len() {
            return Err(FitError::Batch {
                asked: candidates.len(),
                given: signatures.len(),
            });
        }
        evaluations += candidates.len();
        progress(evaluations, best_so_far.get());
        Ok(signatures)
    };
    let start: Vec<f64> = parameters.iter().map(|p| p.start).collect();
    let signature = batch(std::slice::from_ref(&start))?;
    let residuals = Residuals::new(recorded, &signature[0], compared);
    if residuals.keys.is_empty() {
        return Err(FitError::NothingToCompare);
    }
    let r = residuals.of(&signature[0]);
    let start_misfit = residuals.misfit(&r);
    best_so_far.set(start_misfit);
    let mut descents = vec![descend(
        parameters,
        (&residuals, &best_so_far),
        (start, r),
        &mut batch,
        &mut in_budget,
    )?];
    for restart in 1..=restarts {
        if !in_budget() {
            break;
        }
        let x = restart_point(parameters, restart);
        let signature = batch(std::slice::from_ref(&x))?;
        let r = residuals.of(&signature[0]);
        descents.push(descend(
            parameters,
            (&residuals, &best_so_far),
            (x, r),
            &mut batch,
            &mut in_budget,
        )?);
    }
    let lowest = descents
        .iter()
        .map(|d| d.misfit)
        .fold(f64::INFINITY, f64::min);
    let good = |d: &Descent| d.misfit <= lowest * (1.0 + AS_GOOD).powi(2);
    // Of the fits as good as the best, the one that changes the starting profile least (in
    // tolerances): the recordings do not choose between them, so the start does.
    let change = |d: &Descent| {
        d.x.iter()
            .zip(parameters)
            .map(|(v, p)| ((v - p.start) / p.tolerance).powi(2))
            .sum::<f64>()
    };
    let best = descents
        .iter()
        .enumerate()
        .filter(|(_, d)| good(d))
        .min_by(|a, b| change(a.1).total_cmp(&change(b.1)))
        .map_or(0, |(k, _)| k);
    let out_of_budget = descents.iter().any(|d| d.out_of_budget);
    let iterations = descents.iter().map(|d| d.iterations).sum();
    let fits = descents.len();
    // The other fits as good: where they put each parameter.
    let as_good: Vec<Vec<f64>> = descents
        .iter()
        .enumerate()
        .filter(|&(k, d)| k != best && good(d))
        .map(|(_, d)| d.x.clone())
        .collect();
    let Descent { x, r, jacobian, .. } = descents.swap_remove(best);
    // How sure: the Jacobian at the fitted values (measured again if they moved since).
    // Out of budget, the last one measured (near enough for a scale).
    let columns = match jacobian {
        Some((at, columns)) if at == x || out_of_budget => columns,
        _ => jacobian_at(parameters, &x, &r, &residuals, &mut batch)?,
    };
    let misfit = residuals.misfit(&r);
    let (a, _) = normal_equations(&columns, &r);
    let covariances = covariances(&a, &columns, &r, (&residuals.keys, compared.per_bin()));
    let fitted = parameters
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let says_something = a[i][i] > 0.0;
            // The larger of the two: the clustered one is the honest scale, the independent
            // one still sees a direction the recordings say nothing of.
            let standard_error = covariances
                .as_ref()
                .filter(|_| says_something)
                .map(|(independent, clustered)| {
                    let clustered = clustered.as_ref().map_or(0.0, |c| c[i][i]);
                    independent[i][i].max(clustered).max(0.0).sqrt()
                })
                .filter(|se| se.is_finite());
            let trades_off_with = covariances.as_ref().and_then(|(c, _)| {
                (0..parameters.len())
                    .filter(|&j| j != i && a[j][j] > 0.0 && says_something)
                    .map(|j| (j, c[i][j] / (c[i][i] * c[j][j]).sqrt()))
                    .filter(|(_, rho)| rho.abs() >= TRADE_OFF)
                    .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                    .map(|(j, rho)| (parameters[j].name.clone(), rho))
            });
            let also = as_good
                .iter()
                .map(|other| other[i])
                .max_by(|a, b| (a - x[i]).abs().total_cmp(&(b - x[i]).abs()))
                .filter(|other| (other - x[i]).abs() > p.tolerance);
            Fitted {
                name: p.name.clone(),
                value: x[i],
                standard_error,
                tolerance: p.tolerance,
                identified: also.is_none() && standard_error.is_some_and(|se| se <= p.tolerance),
                trades_off_with,
                also,
            }
        })
        .collect();
    Ok(Fit {
        parameters: fitted,
        start_misfit,
        misfit,
        bins: residuals.keys.len(),
        evaluations,
        iterations,
        fits,
        out_of_budget,
    })
}

impl Fit {
    /// The fit of `parameters` where the recordings have nothing to compare: every parameter at
    /// its start, of which they say nothing.
    pub fn nothing_compared(parameters: &[Parameter]) -> Fit {
        Fit {
            parameters: parameters
                .iter()
                .map(|p| Fitted {
                    name: p.name.clone(),
                    value: p.start,
                    standard_error: None,
                    tolerance: p.tolerance,
                    identified: false,
                    trades_off_with: None,
                    also: None,
                })
                .collect(),
            start_misfit: 0.0,
            misfit: 0.0,
            bins: 0,
            evaluations: 0,
            iterations: 0,
            fits: 0,
            out_of_budget: false,
        }
    }
}

/// Restart `k` (from 1): every parameter [`RESTART_TOLERANCES`] tolerances from its start, up or
/// down by a pattern of its own (restart 1 down, up, down, …; 2 the opposite; 3 and 4 in pairs;
/// and so on), within its bounds: far enough to fall into another valley if there is one.
fn restart_point(parameters: &[Parameter], k: usize) -> Vec<f64> {
    let period = 1usize << ((k - 1) / 2).min(16);
    parameters
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let up = (i / period + k).is_multiple_of(2);
            let sign = if up { 1.0 } else { -1.0 };
            (p.start + sign * RESTART_TOLERANCES * p.tolerance).clamp(p.bounds.0, p.bounds.1)
        })
        .collect()
}

/// One Levenberg–Marquardt descent: where it ended, its residuals and the last Jacobian measured.
struct Descent {
    x: Vec<f64>,
    r: Vec<f64>,
    misfit: f64,
    jacobian: Option<(Vec<f64>, Matrix)>,
    iterations: usize,
    out_of_budget: bool,
}

/// A batch of candidates' signatures, or why not.
type Batch<'b> = dyn FnMut(&[Vec<f64>]) -> Result<Vec<Signature>, FitError> + 'b;

/// Levenberg–Marquardt from `x` (residuals `r`), see the module doc; `best` is lowered to every
/// better misfit it finds.
fn descend(
    parameters: &[Parameter],
    (residuals, best): (&Residuals, &std::cell::Cell<f64>),
    (mut x, mut r): (Vec<f64>, Vec<f64>),
    batch: &mut Batch,
    in_budget: &mut dyn FnMut() -> bool,
) -> Result<Descent, FitError> {
    let mut misfit = residuals.misfit(&r);
    let mut lambda = 1e-2;
    let mut jacobian = None;
    let mut out_of_budget = false;
    let mut iterations = 0;
    'iterate: while iterations < MAX_ITERATIONS {
        if !in_budget() {
            out_of_budget = true;
            break;
        }
        iterations += 1;
        let columns = jacobian_at(parameters, &x, &r, residuals, batch)?;
        let (a, g) = normal_equations(&columns, &r);
        jacobian = Some((x.clone(), columns));
        loop {
            if !in_budget() {
                out_of_budget = true;
                break 'iterate;
            }
            let trials: Vec<Vec<f64>> = [lambda, 10.0 * lambda]
                .iter()
                .map(|&l| damped_step(parameters, &x, &a, &g, l))
                .collect();
            let signatures = batch(&trials)?;
            let Some((k, new_r, new_misfit)) = signatures
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    let r = residuals.of(s);
                    let m = residuals.misfit(&r);
                    (k, r, m)
                })
                .min_by(|a, b| a.2.total_cmp(&b.2))
            else {
                break 'iterate;
            };
            if new_misfit < misfit {
                let fall = (misfit - new_misfit) / misfit.max(f64::MIN_POSITIVE);
                let moved = trials[k]
                    .iter()
                    .zip(&x)
                    .zip(parameters)
                    .any(|((new, old), p)| (new - old).abs() > p.step / 20.0);
                lambda = if k == 0 {
                    (lambda / 3.0).max(1e-7)
                } else {
                    10.0 * lambda
                };
                x = trials[k].clone();
                r = new_r;
                misfit = new_misfit;
                best.set(best.get().min(misfit));
                if fall < CONVERGED_RELATIVE || !moved {
                    break 'iterate;
                }
                break;
            }
            lambda *= 100.0;
            if lambda > 1e6 {
                // No damping lowers the misfit: a minimum, as far as the steps can see.
                break 'iterate;
            }
        }
    }
    Ok(Descent {
        x,
        r,
        misfit,
        jacobian,
        iterations,
        out_of_budget,
    })
}

/// A small dense matrix, by rows.
type Matrix = Vec<Vec<f64>>;

/// The covariance of the fitted parameters from `a = JᵀJ`, the Jacobian's `columns` and the
/// residuals `r` of the bins `keys`, two ways: as if every residual were independent, `s² A⁻¹`
/// (whose shape, the correlations, is the design's: what trades off with what), and clustered by
/// test, the sandwich `A⁻¹ (Σ gₜ gₜᵀ) A⁻¹ · T/(T − 1)` with `gₜ = Jₜᵀ rₜ` over test t's residuals,
/// because the bins of one test share its errors (`None` with no more tests than parameters,
/// where it is unsteady).
fn covariances(
    a: &[Vec<f64>],
    columns: &[Vec<f64>],
    r: &[f64],
    (keys, per_bin): (&[(usize, usize, usize)], usize),
) -> Option<(Matrix, Option<Matrix>)> {
    let inverse = inverse_spd(a)?;
    let n = a.len();
    let dof = (r.len() as f64 - n as f64).max(1.0);
    let s2 = r.iter().map(|v| v * v).sum::<f64>() / dof;
    let independent = inverse
        .iter()
        .map(|row| row.iter().map(|v| v * s2).collect())
        .collect();
    let mut by_test: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    for (k, (test, _, _)) in keys.iter().enumerate() {
        let g = by_test.entry(*test).or_insert_with(|| vec![0.0; n]);
        for (i, column) in columns.iter().enumerate() {
            let bin = per_bin * k..per_bin * (k + 1);
            g[i] += column[bin.clone()]
                .iter()
                .zip(&r[bin])
                .map(|(c, r)| c * r)
                .sum::<f64>();
        }
    }
    let tests = by_test.len();
    let clustered = (tests > n).then(|| {
        let correction = tests as f64 / (tests - 1) as f64;
        let meat: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| correction * by_test.values().map(|g| g[i] * g[j]).sum::<f64>())
                    .collect()
            })
            .collect();
        let product = |x: &[Vec<f64>], y: &[Vec<f64>]| -> Vec<Vec<f64>> {
            (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| (0..n).map(|k| x[i][k] * y[k][j]).sum())
                        .collect()
                })
                .collect()
        };
        product(&product(&inverse, &meat), &inverse)
    });
    Some((independent, clustered))
}

/// The Jacobian's columns at `x` (residuals `r`): each parameter moved one step (back, where a
/// step up leaves its bounds), in one batch.
fn jacobian_at(
    parameters: &[Parameter],
    x: &[f64],
    r: &[f64],
    residuals: &Residuals,
    batch: &mut Batch,
) -> Result<Matrix, FitError> {
    let steps: Vec<f64> = parameters
        .iter()
        .zip(x)
        .map(|(p, &v)| {
            if v + p.step <= p.bounds.1 {
                p.step
            } else {
                -p.step
            }
        })
        .collect();
    let candidates: Vec<Vec<f64>> = steps
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let mut c = x.to_vec();
            c[i] += h;
            c
        })
        .collect();
    let signatures = batch(&candidates)?;
    Ok(signatures
        .iter()
        .zip(&steps)
        .map(|(s, h)| {
            residuals
                .of(s)
                .iter()
                .zip(r)
                .map(|(moved, now)| (moved - now) / h)
                .collect()
        })
        .collect())
}

/// `JᵀJ` and `Jᵀr` of the Jacobian's `columns`.
fn normal_equations(columns: &[Vec<f64>], r: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let a = columns
        .iter()
        .map(|ci| columns.iter().map(|cj| dot(ci, cj)).collect())
        .collect();
    let g = columns.iter().map(|c| dot(c, r)).collect();
    (a, g)
}

/// `x` plus the Levenberg–Marquardt step of damping `lambda` (`(A + λ·D) δ = −g`, `D` the
/// diagonal of `A` with a floor so that a parameter the recordings say nothing of stays), within
/// the bounds.
fn damped_step(
    parameters: &[Parameter],
    x: &[f64],
    a: &[Vec<f64>],
    g: &[f64],
    lambda: f64,
) -> Vec<f64> {
    let largest = (0..a.len()).map(|i| a[i][i]).fold(0.0, f64::max);
    let mut damped = a.to_vec();
    for (i, row) in damped.iter_mut().enumerate() {
        row[i] += lambda * a[i][i].max(1e-6 * largest) + 1e-12 * largest;
    }
    let minus_g: Vec<f64> = g.iter().map(|v| -v).collect();
    let delta = solve_spd(&damped, &minus_g).unwrap_or_else(|| vec![0.0; x.len()]);
    x.iter()
        .zip(&delta)
        .zip(parameters)
        .map(|((v, d), p)| {
            let d = if d.is_finite() { *d } else { 0.0 };
            (v + d).clamp(p.bounds.0, p.bounds.1)
        })
        .collect()
}

/// The Cholesky factor `L` of a symmetric positive-definite `a` (`a = L Lᵀ`); `None` when `a` is
/// not positive definite.
fn cholesky(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let sum: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = a[i][i] - sum;
                if d.is_nan() || d <= 0.0 {
                    return None;
                }
                l[i][i] = d.sqrt();
            } else {
                l[i][j] = (a[i][j] - sum) / l[j][j];
            }
        }
    }
    Some(l)
}

/// The solution of `a x = b` for a symmetric positive-definite `a`.
fn solve_spd(a: &[Vec<f64>], b: &[f64]) -> Option<Vec<f64>> {
    let l = cholesky(a)?;
    let n = b.len();
    let mut y = vec![0.0; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

/// The inverse of a symmetric positive-semidefinite `a`: its rows and columns the recordings say
/// nothing of (a zero diagonal) left out, the rest regularised by a millionth of the largest
/// diagonal; `None` when it cannot be inverted.
fn inverse_spd(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let largest = (0..n).map(|i| a[i][i]).fold(0.0, f64::max);
    let mut regular = a.to_vec();
    for (i, row) in regular.iter_mut().enumerate() {
        row[i] += if a[i][i] > 0.0 { 1e-9 * largest } else { 1.0 };
    }
    let mut inverse = vec![vec![0.0; n]; n];
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        let column = solve_spd(&regular, &e)?;
        for (i, v) in column.into_iter().enumerate() {
            inverse[i][j] = v;
        }
    }
    Some(inverse)
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
        let bin = s.bins[&(5, 2, 0)];
        let (e, n) = (bin.east_m, bin.north_m);
        assert!(
            (e - 0.95).abs() < 1e-9 && (n + 1.0).abs() < 1e-12,
            "{e} {n}"
        );
        // Samples 0.1 s apart on a line of slope 1: each moves 0.1 m.
        assert!((bin.jitter_m.unwrap() - 0.1).abs() < 1e-9, "{bin:?}");
        let recorded = s.clone();
        let mut shifted = Signature::default();
        shifted.add_test(5, &samples(|t| (t + 0.1, -1.0)), &[span]);
        let residuals = Residuals::new(&recorded, &shifted, Compared::Means);
        let (j, bins) = (
            residuals.misfit(&residuals.of(&shifted)),
            residuals.keys.len(),
        );
        assert_eq!(bins, 4);
        assert!((j - 0.01).abs() < 1e-9, "{j}");
    }

    /// The jitter sees the radio's noise where the mean does not: two cars with the same mean
    /// error, one with noise of 0.1 m from sample to sample, differ only in it, and a noise
    /// parameter is fitted from it alone.
    #[test]
    fn the_jitter_tells_a_noisier_radio_from_a_quiet_one_of_the_same_mean() {
        let span = SegmentSpan {
            segment_index: START_ROUTE,
            from_s: 0.0,
            to_s: 10.0,
        };
        // Alternating ±sigma around 0.2 m east: the mean stays, each step jumps 2·sigma.
        let noisy = |sigma: f64| {
            let mut s = Signature::default();
            for test in 0..10 {
                let series = samples(|t| {
                    let k = (t * 10.0).round() as i64 + test;
                    (0.2 + if k % 2 == 0 { sigma } else { -sigma }, 0.0)
                });
                s.add_test(test as usize, &series, &[span]);
            }
            s
        };
        let recorded = noisy(0.05);
        let quiet = noisy(0.0);
        for (key, bin) in &recorded.bins {
            assert!(
                (bin.east_m - quiet.bins[key].east_m).abs() < 0.01,
                "{key:?}"
            );
            assert!((bin.jitter_m.unwrap() - 0.1).abs() < 1e-9, "{bin:?}");
        }
        let mean = Signature::mean(&[recorded.clone(), quiet.clone()]);
        assert!((mean.bins[&(0, START_ROUTE, 0)].jitter_m.unwrap() - 0.05).abs() < 1e-9);
        let parameters = [Parameter {
            bounds: (0.0, 1.0),
            ..parameter("sigma", 0.01)
        }];
        let fit = fit(
            &parameters,
            (&recorded, Compared::Jitter),
            0,
            |batch| Ok(batch.iter().map(|x| noisy(x[0])).collect()),
            || true,
            |_, _| {},
        )
        .unwrap();
        let sigma = &fit.parameters[0];
        assert!((sigma.value - 0.05).abs() < 1e-3, "{fit:?}");
        assert!(sigma.identified, "{fit:?}");
        // The start route's means are not compared.
        let means = super::fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(batch.iter().map(|x| noisy(x[0])).collect()),
            || true,
            |_, _| {},
        );
        assert_eq!(means, Err(FitError::NothingToCompare));
    }

    /// A signature of 40 bins, 10 tests of one segment, from a model of `x`: `f(k, x)` is bin
    /// k's (east, north).
    fn model(x: &[f64], f: impl Fn(usize, &[f64]) -> (f64, f64)) -> Signature {
        Signature {
            bins: (0..40)
                .map(|k| {
                    let (east_m, north_m) = f(k, x);
                    let bin = Bin {
                        east_m,
                        north_m,
                        jitter_m: None,
                    };
                    ((k / BINS, 0, k % BINS), bin)
                })
                .collect(),
        }
    }

    fn parameter(name: &str, start: f64) -> Parameter {
        Parameter {
            name: name.to_owned(),
            start,
            step: 0.05,
            tolerance: 0.05,
            bounds: (-2.0, 2.0),
        }
    }

    /// East a·cos k + b·sin k + d + e, north a − b; c does nothing; d and e only as their sum.
    fn linear(k: usize, x: &[f64]) -> (f64, f64) {
        let k = k as f64;
        (x[0] * k.cos() + x[1] * k.sin() + x[3] + x[4], x[0] - x[1])
    }

    #[test]
    fn the_fit_finds_a_linear_models_values_and_names_what_it_cannot_tell_apart() {
        let truth = [0.3, -0.1, 0.0, 0.15, 0.05];
        let mut recorded = model(&truth, linear);
        // A little noise, so that the residuals have a variance.
        for (k, bin) in recorded.bins.values_mut().enumerate() {
            bin.east_m += 0.01 * (7.0 * k as f64).sin();
        }
        let parameters = ["a", "b", "c", "d", "e"].map(|n| parameter(n, 0.0));
        let fit = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(batch.iter().map(|x| model(x, linear)).collect()),
            || true,
            |_, _| {},
        )
        .unwrap();
        let [a, b, c, d, e] = &fit.parameters[..] else {
            panic!()
        };
        assert!((a.value - 0.3).abs() < 0.01, "{a:?}");
        assert!((b.value + 0.1).abs() < 0.01, "{b:?}");
        assert!(a.identified && b.identified, "{a:?} {b:?}");
        assert!(a.standard_error.unwrap() < 0.01, "{a:?}");
        assert!(a.trades_off_with.is_none() && b.trades_off_with.is_none());
        assert_eq!(c.value, 0.0, "a parameter nothing depends on stays");
        assert!(!c.identified && c.standard_error.is_none(), "{c:?}");
        assert!((d.value + e.value - 0.2).abs() < 0.01, "{d:?} {e:?}");
        assert!(!d.identified && !e.identified, "{d:?} {e:?}");
        let (with, rho) = d.trades_off_with.clone().unwrap();
        assert!(with == "e" && rho < -0.99, "{with} {rho}");
        assert!(fit.misfit < 1e-3 * fit.start_misfit, "{fit:?}");
        assert!(!fit.out_of_budget && fit.iterations < 10, "{fit:?}");
        assert_eq!(fit.bins, 40);
    }

    #[test]
    fn the_fit_finds_a_displaced_and_biased_anchor_from_ranges() {
        // Bins along a circle of radius 5 around the origin; the range error to an anchor at
        // (x0, x1) with bias x2 against one at (2, 1) without bias, split along the line of sight.
        let range = |k: usize, x: &[f64]| {
            let angle = k as f64 * 0.157;
            let (px, py) = (5.0 * angle.cos(), 5.0 * angle.sin());
            let to = |ax: f64, ay: f64| ((px - ax).powi(2) + (py - ay).powi(2)).sqrt();
            let error = to(x[0], x[1]) + x[2] - to(2.0, 1.0);
            let d = to(2.0, 1.0);
            (error * (px - 2.0) / d, error * (py - 1.0) / d)
        };
        let recorded = model(&[2.35, 0.8, 0.1], range);
        let parameters = [
            parameter("x", 2.0),
            parameter("y", 1.0),
            parameter("bias", 0.0),
        ]
        .map(|p| Parameter {
            bounds: (-5.0, 5.0),
            ..p
        });
        let fit = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(batch.iter().map(|x| model(x, range)).collect()),
            || true,
            |_, _| {},
        )
        .unwrap();
        let values: Vec<f64> = fit.parameters.iter().map(|p| p.value).collect();
        for (v, truth) in values.iter().zip([2.35, 0.8, 0.1]) {
            assert!((v - truth).abs() < 0.005, "{values:?} {fit:?}");
        }
        assert!(fit.parameters.iter().all(|p| p.identified), "{fit:?}");
    }

    #[test]
    fn the_standard_error_counts_a_tests_bins_as_one() {
        // a moves every east error; each of 10 tests has an error of its own, ±0.1 m, in all
        // its bins: a is known to 0.1/√10, not to 0.1/√40 (bins) or less.
        let parameters = [parameter("a", 0.0)];
        let recorded = model(&[0.3], |k, x| {
            let test = k / BINS;
            (
                x[0] + 0.1 * if test.is_multiple_of(2) { 1.0 } else { -1.0 },
                0.0,
            )
        });
        let fit = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(batch.iter().map(|x| model(x, |_, x| (x[0], 0.0))).collect()),
            || true,
            |_, _| {},
        )
        .unwrap();
        let a = &fit.parameters[0];
        assert!((a.value - 0.3).abs() < 1e-3, "{a:?}");
        let expected = 0.1 / 10f64.sqrt() * (10.0f64 / 9.0).sqrt();
        let se = a.standard_error.unwrap();
        assert!((se - expected).abs() < 1e-3, "{se} against {expected}");
    }

    #[test]
    fn a_restart_finds_a_second_valley_and_the_parameter_is_not_identified() {
        // East x² at every bin: x = 0.3 and x = −0.3 fit alike; y is linear and known.
        let f = |_: usize, x: &[f64]| (x[0] * x[0], x[1]);
        let recorded = model(&[0.3, 0.2], |k, x| {
            let (e, n) = f(k, x);
            (e + 0.01 * (k as f64).sin(), n)
        });
        let parameters = [parameter("x", 0.1), parameter("y", 0.0)];
        let run = |restarts| {
            fit(
                &parameters,
                (&recorded, Compared::Means),
                restarts,
                |batch| Ok(batch.iter().map(|x| model(x, f)).collect()),
                || true,
                |_, _| {},
            )
            .unwrap()
        };
        let alone = run(0);
        assert!((alone.parameters[0].value - 0.3).abs() < 0.01, "{alone:?}");
        assert!(
            alone.parameters[0].identified && alone.fits == 1,
            "{alone:?}"
        );
        let restarted = run(2);
        let x = &restarted.parameters[0];
        assert_eq!(restarted.fits, 3);
        assert!(!x.identified, "{restarted:?}");
        let also = x.also.unwrap();
        assert!(
            (also.abs() - 0.3).abs() < 0.01 && also * x.value < 0.0,
            "{x:?}"
        );
        let y = &restarted.parameters[1];
        assert!(
            y.identified && y.also.is_none() && (y.value - 0.2).abs() < 0.01,
            "{y:?}"
        );
    }

    #[test]
    fn the_budget_ends_the_fit_with_the_best_so_far() {
        let recorded = model(&[0.3, -0.1, 0.0, 0.2, 0.0], linear);
        let parameters = ["a", "b", "c", "d", "e"].map(|n| parameter(n, 0.0));
        let mut calls = 0;
        let fit = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(batch.iter().map(|x| model(x, linear)).collect()),
            || {
                calls += 1;
                calls < 3
            },
            |_, _| {},
        )
        .unwrap();
        assert!(fit.out_of_budget && fit.iterations == 1, "{fit:?}");
        assert!(fit.misfit < fit.start_misfit);
    }

    #[test]
    fn a_batch_of_the_wrong_size_and_nothing_to_compare_are_errors() {
        let recorded = model(&[0.0; 5], linear);
        let parameters = ["a", "b", "c", "d", "e"].map(|n| parameter(n, 0.0));
        let wrong = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |_| Ok(vec![]),
            || true,
            |_, _| {},
        );
        assert_eq!(wrong, Err(FitError::Batch { asked: 1, given: 0 }));
        let nothing = fit(
            &parameters,
            (&recorded, Compared::Means),
            0,
            |batch| Ok(vec![Signature::default(); batch.len()]),
            || true,
            |_, _| {},
        );
        assert_eq!(nothing, Err(FitError::NothingToCompare));
    }
}
