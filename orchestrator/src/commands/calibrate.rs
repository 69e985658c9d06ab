//! `drivecheck calibrate`: a car profile fitted to recordings of a car. The recorded cases are
//! driven again on embedded simulated cars of candidate profiles in virtual time, and the
//! profile's anchors, odometry scale and yaw bias are fitted so that the simulated UWB − RTK error
//! matches the recorded one (the method is `campaign::calibrate`'s; `docs/twin.md`). Only what a
//! car reports is read: case files, state samples, commands and acks; never `/sim/*` or a
//! recorded profile.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};

use super::shared::{cancel_on_ctrl_c, check_hash, runtime, scenario_of};
use super::simdrive::{SimDriver, SimSettings};
use crate::cli::CalibrateArgs;
use crate::exit::Exit;
use crate::profile_arg::LoadedProfile;
use crate::report::explain::{TestErrors, error_series};
use campaign::calibrate::{Fit, Parameter, Signature, fit, misfit};
use campaign::files::Case;
use campaign::seed::{Purpose, derive};
use car_sim::CarProfile;
use car_sim::profile::AnchorProfile;

/// A recorded test to compare: where it came from and its recorded signature's key.
struct Recorded {
    path: PathBuf,
    errors: TestErrors,
}

/// The fitted parameters of `scenario`'s anchors, the odometry and the IMU, starting at `start`.
fn parameters(start: &CarProfile, scenario: &scenarios::Scenario) -> Vec<Parameter> {
    let mut parameters = Vec::new();
    let radio = start.radio_model();
    for anchor in &scenario.anchors {
        let known = start.anchors.get(&anchor.id);
        let offset = known.map_or([0.0, 0.0], |a| a.offset_m);
        let bias = known
            .and_then(|a| a.range_bias_m)
            .unwrap_or_else(|| radio.drawn_bias(anchor.id));
        for (axis, value) in offset.into_iter().enumerate() {
            parameters.push(Parameter {
                name: format!("anchors.\"{}\".offset_m[{axis}]", anchor.id),
                start: value,
                step: 0.2,
                resolution: 0.02,
                bounds: (-1.5, 1.5),
            });
        }
        parameters.push(Parameter {
            name: format!("anchors.\"{}\".range_bias_m", anchor.id),
            start: bias,
            step: 0.1,
            resolution: 0.01,
            bounds: (-1.0, 1.0),
        });
    }
    parameters.push(Parameter {
        name: "odometry.scale".to_owned(),
        start: start.odometry.scale,
        step: 0.02,
        resolution: 0.002,
        bounds: (0.9, 1.1),
    });
    parameters.push(Parameter {
        name: "imu.yaw_bias_deg".to_owned(),
        start: start.imu.yaw_bias_deg,
        step: 1.0,
        resolution: 0.1,
        bounds: (-5.0, 5.0),
    });
    parameters
}

/// `start` with the fitted `values` (in [`parameters`]' order).
fn candidate(start: &CarProfile, scenario: &scenarios::Scenario, values: &[f64]) -> CarProfile {
    let mut profile = start.clone();
    for (k, anchor) in scenario.anchors.iter().enumerate() {
        let v = &values[3 * k..3 * k + 3];
        profile.anchors.insert(
            anchor.id,
            AnchorProfile {
                offset_m: [v[0], v[1]],
                range_bias_m: Some(v[2]),
            },
        );
    }
    let n = 3 * scenario.anchors.len();
    profile.odometry.scale = values[n];
    profile.imu.yaw_bias_deg = values[n + 1];
    profile
}

/// Drives every recorded test on `profile` (`runs` runs each, the same seeds for every
/// candidate) and returns the simulated signature.
fn simulate(
    profile: &CarProfile,
    scenario: &scenarios::Scenario,
    recorded: &[Recorded],
    runs: u32,
    scratch: &std::path::Path,
) -> Result<Signature> {
    let loaded = LoadedProfile {
        profile: profile.clone(),
        name: "candidate".to_owned(),
    };
    let sim = loaded.sim_config(scenario)?;
    let runtime = runtime(true)?;
    let cancel = runtime.block_on(async { cancel_on_ctrl_c() });
    let mut runs_of: Vec<Signature> = vec![Signature::default(); runs as usize];
    for test in recorded {
        let case: &Case = &test.errors.case;
        let test_index = case.test_index.unwrap_or_default();
        let seed = derive(case.campaign_seed.unwrap_or_default(), Purpose::Calibration);
        let mut driver = SimDriver::new(
            (scenario, sim.clone()),
            &test.path,
            case,
            scratch.to_owned(),
            (runs, seed),
            &cancel,
        );
        driver.record = true;
        // Every segment driven, whatever fails: a candidate must not compare fewer bins by
        // failing early.
        driver.policy = campaign::oracle::FailurePolicy::ContinueAndRecord;
        let plan = driver.plan(case)?;
        for (k, signature) in runs_of.iter_mut().enumerate() {
            let seed = derive(seed, Purpose::Run { run: k as u64 });
            runtime.block_on(driver.drive_once(&plan, seed, &SimSettings::default()))?;
            for run in error_series(&driver.run_dir(), scenario)? {
                signature.add_test(test_index, &run.samples, &run.spans);
            }
        }
    }
    Ok(Signature::mean(&runs_of))
}

/// `drivecheck calibrate`. Exit status: 0 fitted, 2 error.
pub fn calibrate(args: &CalibrateArgs) -> Result<Exit> {
    let started = Instant::now();
    let mut recorded = Vec::new();
    let mut scenario = None;
    for dir in &args.runs {
        let files = super::shared::case_files(dir)?;
        let Some(first) = files.first() else {
            bail!("{}: no case files", dir.display());
        };
        let first_case = super::shared::read_case(first)?;
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
        for errors in tests {
            recorded.push(Recorded {
                path: dir.join(&errors.file),
                errors,
            });
        }
    }
    let Some(scenario) = scenario else {
        bail!("give at least one run directory");
    };
    let mut signature = Signature::default();
    for test in &recorded {
        let index = test.errors.case.test_index.unwrap_or_default();
        signature.add_test(index, &test.errors.samples, &test.errors.spans);
    }
    let start = LoadedProfile::load(args.from.as_deref())?;
    let parameters = parameters(&start.profile, &scenario);
    let scratch = std::env::temp_dir().join(format!("drivecheck-calibrate-{}", std::process::id()));
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{elapsed_precise} {spinner} {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    eprintln!(
        "calibrating {} parameters on {} recorded test(s), {} simulated run(s) each, budget {}",
        parameters.len(),
        recorded.len(),
        args.sim_runs,
        humantime::format_duration(args.budget)
    );
    let evaluations = std::cell::Cell::new(0usize);
    let result = fit(
        &parameters,
        |values| {
            let profile = candidate(&start.profile, &scenario, values);
            let simulated = simulate(&profile, &scenario, &recorded, args.sim_runs, &scratch)
                .map_err(|e| format!("{e:#}"))?;
            Ok(misfit(&signature, &simulated))
        },
        || {
            started.elapsed() < args.budget
                && args
                    .max_evaluations
                    .is_none_or(|max| evaluations.get() < max as usize)
        },
        |count, best| {
            evaluations.set(count);
            bar.set_message(format!(
                "evaluation {count}: misfit {:.4} m² (rms {:.3} m)",
                best,
                best.sqrt()
            ));
        },
    );
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&scratch);
    let fit = result?;
    let values: Vec<f64> = fit.parameters.iter().map(|p| p.value).collect();
    let profile = candidate(&start.profile, &scenario, &values);
    profile.check(&args.out.display().to_string())?;
    let text = format!(
        "{}{}",
        header(&fit, args, started.elapsed()),
        profile.to_toml()
    );
    crate::atomic::write(&args.out, text)?;
    print!("{}", table(&fit));
    println!(
        "written: {} ({} evaluations, {:.0} s{})",
        args.out.display(),
        fit.evaluations,
        started.elapsed().as_secs_f64(),
        if fit.out_of_budget {
            "; the budget (--budget, --max-evaluations) ended the search: give more for a finer fit"
        } else {
            ""
        }
    );
    Ok(Exit::Success)
}

/// The comment the profile file begins with: where it came from and how well it fits.
fn header(fit: &Fit, args: &CalibrateArgs, wall: std::time::Duration) -> String {
    let mut out = format!(
        "# Calibrated by drivecheck {} from {} in {:.0} s: rms misfit {:.3} m (start {:.3} m) over {} bins.\n",
        campaign::files::tool_version(),
        args.runs
            .iter()
            .map(|r| r.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        wall.as_secs_f64(),
        fit.misfit.sqrt(),
        fit.start_misfit.sqrt(),
        fit.bins
    );
    for p in &fit.parameters {
        out.push_str(&format!(
            "# {} = {:.4}{}\n",
            p.name,
            p.value,
            match (p.identified, p.standard_error) {
                (false, _) => " (not identified by the recordings: kept)".to_owned(),
                (true, Some(se)) => format!(" ± {se:.4}"),
                (true, None) => String::new(),
            }
        ));
    }
    out.push_str(
        "# Not fitted (kept from the starting profile): firmware, radio noise and losses, GNSS, yaw drift.\n\n",
    );
    out
}

/// The fitted parameters as a table.
fn table(fit: &Fit) -> String {
    let mut out =
        String::from("| parameter | fitted | standard error | identified |\n|---|---|---|---|\n");
    for p in &fit.parameters {
        out.push_str(&format!(
            "| {} | {:.3} | {} | {} |\n",
            p.name,
            p.value,
            p.standard_error
                .map_or_else(|| "-".to_owned(), |se| format!("{se:.3}")),
            if p.identified {
                "yes"
            } else {
                "no: the recordings cannot tell its values apart (kept)"
            }
        ));
    }
    out.push_str(&format!(
        "\nfit: rms misfit {:.3} m (start {:.3} m) over {} bins of the recorded UWB − RTK error\n",
        fit.misfit.sqrt(),
        fit.start_misfit.sqrt(),
        fit.bins
    ));
    out
}
