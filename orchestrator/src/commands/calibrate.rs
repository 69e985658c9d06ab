//! `drivecheck calibrate`: a car profile fitted to recordings of a car. The recorded cases are
//! driven again on embedded simulated cars of candidate profiles in virtual time, and the
//! radio's ranging and NLOS noise (on the error's jitter), then the anchors, odometry scale and
//! yaw bias (on its means) are fitted so that the simulated UWB − RTK error matches the recorded
//! one (the method is `campaign::calibrate`'s; `docs/twin.md`). Only what a car reports is read:
//! case files, state samples, commands and acks; never `/sim/*` or a recorded profile.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::ProgressStyle;
use tokio_util::sync::CancellationToken;

use super::case_input::{check_hash, scenario_of};
use super::signals::{cancel_on_ctrl_c, runtime};
use crate::cli::CalibrateArgs;
use crate::exit::Exit;
use crate::profile_arg::LoadedProfile;
use campaign::calibrate::{Compared, Fit, FitError, Fitted, Parameter, Signature, fit};
use campaign::model::TestPlan;
use campaign::seed::{Purpose, derive};
use car_sim::CarProfile;
use car_sim::profile::Target;
use report::explain::{TestErrors, error_series};
use runner::simdrive::{SimDriver, SimSettings};

/// The fitted parameters: `scenario`'s anchors, the odometry and the IMU, starting at `start`;
/// each with where its value goes (the one place that orders them).
fn parameters(start: &CarProfile, scenario: &scenarios::Scenario) -> Vec<(Parameter, Target)> {
    let mut parameters = Vec::new();
    let radio = start.radio_model();
    // Steps wide enough to see past the simulated misfit's roughness; tolerances those a twin
    // needs (docs/twin.md: anchors within 0.1 m, biases within 0.05 m).
    let parameter =
        |name: String, start: f64, step: f64, tolerance: f64, bounds: (f64, f64)| Parameter {
            name,
            start,
            step,
            tolerance,
            bounds,
        };
    for anchor in &scenario.anchors {
        let known = start.anchors.get(&anchor.id);
        let offset = known.map_or([0.0, 0.0], |a| a.offset_m);
        let bias = known
            .and_then(|a| a.range_bias_m)
            .unwrap_or_else(|| radio.drawn_bias(anchor.id));
        for (axis, value) in offset.into_iter().enumerate() {
            parameters.push((
                parameter(
                    format!("anchors.\"{}\".offset_m[{axis}]", anchor.id),
                    value,
                    0.1,
                    0.1,
                    (-2.0, 2.0),
                ),
                Target::Offset(anchor.id, axis),
            ));
        }
        parameters.push((
            parameter(
                format!("anchors.\"{}\".range_bias_m", anchor.id),
                bias,
                0.05,
                0.05,
                (-1.0, 1.0),
            ),
            Target::Bias(anchor.id),
        ));
    }
    parameters.push((
        parameter(
            "odometry.scale".to_owned(),
            start.odometry.scale,
            0.01,
            0.01,
            (0.9, 1.1),
        ),
        Target::OdometryScale,
    ));
    parameters.push((
        parameter(
            "imu.yaw_bias_deg".to_owned(),
            start.imu.yaw_bias_deg,
            0.5,
            0.5,
            (-5.0, 5.0),
        ),
        Target::YawBias,
    ));
    parameters
}

/// The radio's parameters, fitted first and on the bins' jitter alone (`Compared::Jitter`: the
/// error's jumps from sample to sample, which the anchors, the odometry and the IMU barely move),
/// starting at `start`'s: the ranging noise and the NLOS ranges' extra noise. Not the share of
/// exchanges lost: in the jitter it trades off with the noise (fewer corrections, each larger),
/// and on car F of `drivecheck-dev bench twin-reach` the fit put it at 0.001 against the car's
/// 0.12 and still called it identified (docs/twin.md).
fn radio_parameters(start: &CarProfile) -> Vec<(Parameter, Target)> {
    let parameter = |name: &str, start: f64, step: f64, bounds: (f64, f64), target: Target| {
        let p = Parameter {
            name: name.to_owned(),
            start,
            step,
            tolerance: 0.05,
            bounds,
        };
        (p, target)
    };
    vec![
        parameter(
            "radio.range_sigma_m",
            start.radio.range_sigma_m,
            0.02,
            (0.0, 0.5),
            Target::RangeSigma,
        ),
        parameter(
            "radio.nlos_extra_sigma_m",
            start.radio.nlos_extra_sigma_m,
            0.05,
            (0.0, 1.0),
            Target::NlosSigma,
        ),
    ]
}

/// A recorded test, ready to drive again: its case file, case, plan (cut where the recording
/// stops saying anything, see [`cut`]) and the seed of its runs.
struct Prepared {
    path: PathBuf,
    errors: TestErrors,
    plan: TestPlan,
    seed: u64,
}

/// `plan` without the segments after `last_compared + 2`: the compared segments end where the
/// car enters the next one, and one more keeps the car from braking for the route's end before
/// that (the ahead margin is shorter than two segments). What comes after is never compared
/// (only stretches before the first fault are), so driving it is time lost.
fn cut(mut plan: TestPlan, last_compared: usize) -> TestPlan {
    let keep = plan
        .segments()
        .nth(last_compared + 2)
        .map(|(index, _)| index + 1);
    if let Some(keep) = keep {
        plan.commands.truncate(keep);
    }
    plan
}

/// Drives the recorded tests on candidate profiles: `jobs` candidates at once, each on threads
/// of its own with a runtime in virtual time and a scratch directory.
struct Simulator<'a> {
    scenario: &'a scenarios::Scenario,
    start: CarProfile,
    targets: Vec<Target>,
    tests: Vec<Prepared>,
    runs: u32,
    jobs: usize,
    scratch: PathBuf,
    cancel: &'a CancellationToken,
    /// With `--car sitl:TREE`: the car's own firmware, driven in each candidate's physical car.
    firmware: Option<super::firmware::HostFirmware>,
}

impl Simulator<'_> {
    /// The signature of each candidate (its values in the targets' order), in order.
    fn signatures(&self, candidates: &[Vec<f64>]) -> Result<Vec<Signature>> {
        let next = std::sync::atomic::AtomicUsize::new(0);
        let mut results: Vec<(usize, Result<Signature>)> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..self.jobs.min(candidates.len()))
                .map(|job| {
                    let next = &next;
                    scope.spawn(move || {
                        let scratch = self.scratch.join(format!("job-{job}"));
                        let mut mine = Vec::new();
                        loop {
                            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            let Some(values) = candidates.get(k) else {
                                return mine;
                            };
                            let profile = self.start.with_values(&self.targets, values);
                            mine.push((k, self.simulate(&profile, &scratch)));
                        }
                    })
                })
                .collect();
            workers
                .into_iter()
                .flat_map(|w| {
                    w.join().unwrap_or_else(|_| {
                        vec![(usize::MAX, Err(anyhow::anyhow!("a driving thread failed")))]
                    })
                })
                .collect()
        });
        results.sort_by_key(|(k, _)| *k);
        results.into_iter().map(|(_, r)| r).collect()
    }

    /// The signature of `profile`: every recorded test driven `runs` times (the same seeds for
    /// every candidate), the runs' mean.
    fn simulate(&self, profile: &CarProfile, scratch: &Path) -> Result<Signature> {
        let loaded = LoadedProfile {
            profile: profile.clone(),
            name: "candidate".to_owned(),
        };
        let sim = loaded.sim_config(self.scenario)?;
        let runtime = runtime(true)?;
        let mut runs_of: Vec<Signature> = vec![Signature::default(); self.runs as usize];
        for test in &self.tests {
            let case = &test.errors.case;
            let test_index = case.test_index.unwrap_or_default();
            let mut driver = SimDriver::new(
                (self.scenario, sim.clone()),
                &test.path,
                case,
                scratch.to_owned(),
                (self.runs, test.seed),
                self.cancel,
            );
            driver.record = true;
            driver.firmware = self.firmware.clone();
            // Every segment driven, whatever fails: a candidate must not compare fewer bins by
            // failing early.
            driver.policy = campaign::oracle::FailurePolicy::ContinueAndRecord;
            for (k, signature) in runs_of.iter_mut().enumerate() {
                let seed = derive(test.seed, Purpose::Run { run: k as u64 });
                runtime.block_on(driver.drive_once(&test.plan, seed, &SimSettings::default()))?;
                for run in error_series(&driver.run_dir(), self.scenario)? {
                    signature.add_test(test_index, &run.samples, &run.spans);
                }
            }
        }
        Ok(Signature::mean(&runs_of))
    }
}

/// `drivecheck calibrate`. Exit status: 0 fitted, 2 error.
pub fn calibrate(args: &CalibrateArgs) -> Result<Exit> {
    let started = Instant::now();
    let mut recorded = Vec::new();
    let mut scenario = None;
    for dir in &args.runs {
        let files = super::case_input::case_files(dir)?;
        let Some(first) = files.first() else {
            bail!("{}: no case files", dir.display());
        };
        let first_case = super::case_input::read_case(first)?;
        let s = match &scenario {
            Some(s) => s,
            None => scenario.insert(scenario_of(args.scenario.as_deref(), first, &first_case)?),
        };
        check_hash(&first_case, s, args.ignore_scenario_hash)?;
        let tests =
            error_series(dir, s).with_context(|| format!("cannot read {}", dir.display()))?;
        if tests.is_empty() {
            bail!(
                "{}: its recording holds no state samples (record with --record all)",
                dir.display()
            );
        }
        recorded.extend(
            tests
                .into_iter()
                .map(|errors| (dir.join(&errors.file), errors)),
        );
    }
    let Some(scenario) = scenario else {
        bail!("give at least one run directory");
    };
    let start = crate::profile_arg::load(args.from.as_deref())?;
    let firmware = super::firmware::fresh_car("calibrate", &args.car)?;
    let start_sim = start.sim_config(&scenario)?;
    let interrupt_runtime = runtime(false)?;
    let cancel = interrupt_runtime.block_on(async { cancel_on_ctrl_c() });
    let scratch = std::env::temp_dir().join(format!("drivecheck-calibrate-{}", std::process::id()));
    let mut signature = Signature::default();
    let mut tests = Vec::new();
    for (path, errors) in recorded {
        let test_index = errors.case.test_index.unwrap_or_default();
        let mut own = Signature::default();
        own.add_test(test_index, &errors.samples, &errors.spans);
        if own.bins.is_empty() {
            continue; // nothing of it to compare
        }
        let last_compared = own
            .bins
            .keys()
            .map(|&(_, segment, _)| segment)
            .filter(|&segment| segment != campaign::calibrate::START_ROUTE)
            .max()
            .unwrap_or(0);
        signature.bins.extend(own.bins);
        let seed = derive(
            errors.case.campaign_seed.unwrap_or_default(),
            Purpose::Calibration,
        );
        let driver = SimDriver::new(
            (&scenario, start_sim.clone()),
            &path,
            &errors.case,
            scratch.clone(),
            (args.sim_runs, seed),
            &cancel,
        );
        let plan = cut(driver.plan(&errors.case)?, last_compared);
        tests.push(Prepared {
            path,
            errors,
            plan,
            seed,
        });
    }
    if tests.is_empty() {
        bail!(
            "no recorded test has a stretch before its first fault to compare (its start route or a judged segment)"
        );
    }
    let (radio, radio_targets): (Vec<Parameter>, Vec<Target>) =
        radio_parameters(&start.profile).into_iter().unzip();
    let (parameters, targets): (Vec<Parameter>, Vec<Target>) =
        parameters(&start.profile, &scenario).into_iter().unzip();
    let jobs = args.jobs.map_or_else(
        || std::thread::available_parallelism().map_or(1, usize::from),
        |j| j as usize,
    );
    let mut simulator = Simulator {
        scenario: &scenario,
        start: start.profile.clone(),
        targets: radio_targets.clone(),
        tests,
        runs: args.sim_runs,
        jobs,
        scratch: scratch.clone(),
        cancel: &cancel,
        firmware,
    };
    let bar = crate::output::bar(None);
    if let Ok(style) = ProgressStyle::with_template("{elapsed_precise} {spinner} {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    crate::output::progress(format_args!(
        "calibrating {} parameters on {} recorded test(s) ({} stretches), {} simulated run(s) each on {}, {} at once, budget {}",
        radio.len() + parameters.len(),
        simulator.tests.len(),
        signature.bins.len(),
        args.sim_runs,
        simulator.firmware.as_ref().map_or_else(
            || "the embedded simulated car".to_owned(),
            |f| format!("the firmware {} built for the host", f.version)
        ),
        jobs,
        humantime::format_duration(args.budget)
    ));
    let evaluations = std::cell::Cell::new(0usize);
    // First the radio on the jitter, then the rest on the means with that radio (see
    // `Compared`): one fit of both would put the radio's noise low whatever the car.
    let stage = |simulator: &Simulator, parameters: &[Parameter], compared, what: &str| {
        let before = evaluations.get();
        fit(
            parameters,
            (&signature, compared),
            args.restarts as usize,
            |batch| simulator.signatures(batch).map_err(|e| format!("{e:#}")),
            || {
                started.elapsed() < args.budget
                    && args
                        .max_evaluations
                        .is_none_or(|max| evaluations.get() < max as usize)
            },
            |count, best| {
                evaluations.set(before + count);
                bar.set_message(format!(
                    "{what}: {} candidates: misfit {best:.4} m² (rms {:.3} m)",
                    before + count,
                    best.sqrt()
                ));
            },
        )
    };
    // A stage with nothing to compare keeps its parameters (the table says the recordings say
    // nothing of them); with nothing for either there is no fit.
    let or_kept = |fitted: Result<Fit, FitError>, parameters: &[Parameter]| match fitted {
        Err(FitError::NothingToCompare) => Ok(Fit::nothing_compared(parameters)),
        other => other,
    };
    let radio_fit = or_kept(
        stage(&simulator, &radio, Compared::Jitter, "the radio"),
        &radio,
    );
    let result = radio_fit.and_then(|radio_fit| {
        let values: Vec<f64> = radio_fit.parameters.iter().map(|p| p.value).collect();
        simulator.start = start.profile.with_values(&radio_targets, &values);
        simulator.targets = targets.clone();
        let rest = or_kept(
            stage(
                &simulator,
                &parameters,
                Compared::Means,
                "anchors, odometry, IMU",
            ),
            &parameters,
        )?;
        if radio_fit.bins + rest.bins == 0 {
            return Err(FitError::NothingToCompare);
        }
        Ok((radio_fit, rest))
    });
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&scratch);
    let (radio_fit, fit) = result?;
    let values: Vec<f64> = fit.parameters.iter().map(|p| p.value).collect();
    let profile = simulator.start.with_values(&targets, &values);
    profile.check(&args.out.display().to_string())?;
    let text = format!(
        "{}{}",
        header(
            (&radio_fit, &fit),
            (args, simulator.firmware.as_ref()),
            started.elapsed()
        ),
        profile.to_toml()
    );
    runner::atomic::write(&args.out, text)?;
    print!("{}", table((&radio_fit, &fit)));
    let out_of_budget = radio_fit.out_of_budget || fit.out_of_budget;
    println!(
        "written: {} ({} candidates, {} descent(s) of {} iterations in all, {:.0} s{})",
        args.out.display(),
        radio_fit.evaluations + fit.evaluations,
        radio_fit.fits + fit.fits,
        radio_fit.iterations + fit.iterations,
        started.elapsed().as_secs_f64(),
        if out_of_budget {
            "; the budget (--budget, --max-evaluations) ended a descent before it converged: give more for a finer fit and more restarts"
        } else {
            ""
        }
    );
    Ok(Exit::Success)
}

/// Whether the recordings identify `p`, in words.
fn identification(p: &Fitted) -> String {
    if p.identified {
        return "yes".to_owned();
    }
    if let Some(also) = p.also {
        return format!("no: another fit as good puts it at {also:.3}");
    }
    match (&p.trades_off_with, p.standard_error) {
        (_, None) => "no: the recordings say nothing of it (kept)".to_owned(),
        (Some((with, rho)), Some(_)) => format!(
            "no: trades off with {with} (correlation {rho:+.2}): only their combination is fitted"
        ),
        (None, Some(_)) => format!(
            "no: the recordings cannot tell its values apart to ±{}",
            p.tolerance
        ),
    }
}

/// The comment the profile file begins with: where it came from and how well it fits.
fn header(
    (radio, fit): (&Fit, &Fit),
    (args, firmware): (&CalibrateArgs, Option<&super::firmware::HostFirmware>),
    wall: std::time::Duration,
) -> String {
    let mut out = format!(
        "# Calibrated by drivecheck {} from {}{} in {:.0} s: rms misfit {:.3} m (start {:.3} m) over {} bins; the radio's, of the jitter, {:.4} m (start {:.4} m) over {} bins.\n",
        campaign::files::tool_version(),
        args.runs
            .iter()
            .map(|r| r.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        firmware.map_or_else(String::new, |f| format!(
            " on the firmware {} built for the host (tree {})",
            f.version, f.tree_hash
        )),
        wall.as_secs_f64(),
        fit.misfit.sqrt(),
        fit.start_misfit.sqrt(),
        fit.bins,
        radio.misfit.sqrt(),
        radio.start_misfit.sqrt(),
        radio.bins
    );
    for p in radio.parameters.iter().chain(&fit.parameters) {
        out.push_str(&format!(
            "# {} = {:.4}{}; identified: {}\n",
            p.name,
            p.value,
            p.standard_error
                .map_or_else(String::new, |se| format!(" ± {se:.4}")),
            identification(p)
        ));
    }
    out.push_str(
        "# Not fitted (kept from the starting profile): firmware, the share of exchanges lost, GNSS, yaw drift.\n\n",
    );
    out
}

/// The fitted parameters as a table.
fn table((radio, fit): (&Fit, &Fit)) -> String {
    let mut out =
        String::from("| parameter | fitted | standard error | identified |\n|---|---|---|---|\n");
    for p in radio.parameters.iter().chain(&fit.parameters) {
        out.push_str(&format!(
            "| {} | {:.3} | {} | {} |\n",
            p.name,
            p.value,
            p.standard_error
                .map_or_else(|| "-".to_owned(), |se| format!("{se:.3}")),
            identification(p)
        ));
    }
    out.push_str(&format!(
        "\nfit: rms misfit {:.3} m (start {:.3} m) over {} bins of the recorded UWB − RTK error; the radio: rms misfit of the jitter {:.4} m (start {:.4} m) over {} bins\n",
        fit.misfit.sqrt(),
        fit.start_misfit.sqrt(),
        fit.bins,
        radio.misfit.sqrt(),
        radio.start_misfit.sqrt(),
        radio.bins
    ));
    out
}
