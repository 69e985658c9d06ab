//! `drivecheck sweep CASE.json --set NAME=V1,V2,…`: the case driven for every value (or every
//! combination of several `--set`s) on the embedded simulated car in virtual time, `--runs` times
//! each (run k with seed + k), and a table of each segment's largest deviation per value (JSON
//! with `--json`). The pure part (parameters, grid, result) is [`campaign::sweep`].

use anyhow::{Context, Result};

use super::signals::{cancel_on_ctrl_c, runtime};
use crate::cli::SweepArgs;
use crate::exit::Exit;
use crate::output;
use crate::settings::CaseSettings;
use campaign::files::{Header, SWEEP_FORMAT, SWEEP_SCHEMA_VERSION, ScenarioRef};
use campaign::sweep::{Axis, Parameter, Point, SimSetting, SweepReport, grid, with_fault_values};
use runner::simdrive::{SimDriver, SimSettings};

/// Runs the sweep and prints its table (or JSON). Exit status 0 when it ran, 2 on an error.
pub fn sweep(args: &SweepArgs) -> Result<Exit> {
    let path = &args.case;
    let CaseSettings {
        case,
        scenario,
        seed,
        firmware,
        profile,
        sim,
        ..
    } = CaseSettings::load("sweep", path, &args.drive, false)?;
    let axes = args
        .set
        .iter()
        .map(|arg| Axis::parse(arg, &case))
        .collect::<Result<Vec<_>, _>>()?;
    campaign::sweep::grid_size(&axes)?;
    let points = grid(&axes);
    output::progress(format_args!(
        "sweeping {} over {} point(s), {} run(s) each, seed {seed}",
        path.display(),
        points.len(),
        args.runs
    ));
    // The runs' scratch run directories (unrecorded), removed at the end.
    let scratch = std::env::temp_dir().join(format!("drivecheck-sweep-{}", std::process::id()));
    let report = runtime(true)?.block_on(async {
        let cancel = cancel_on_ctrl_c();
        let mut driver = SimDriver::new(
            (&scenario, sim.clone()),
            path,
            &case,
            scratch.clone(),
            (args.runs, seed),
            &cancel,
        );
        driver.firmware = firmware;
        let mut results = Vec::with_capacity(points.len());
        for values in points {
            let swept = with_fault_values(&case, &axes, &values);
            let settings = sim_settings(&axes, &values);
            let what = describe(&axes, &values);
            let driven = driver
                .drive_all(&swept, &settings)
                .await
                .with_context(|| what.clone())?;
            let point = Point::new(values, &driven);
            output::progress(format_args!(
                "{what}: {} of {} runs failed",
                point.failed_runs(),
                point.runs.len()
            ));
            results.push(point);
        }
        anyhow::Ok(SweepReport {
            header: Header::current(SWEEP_FORMAT, SWEEP_SCHEMA_VERSION),
            case: path.display().to_string(),
            scenario: ScenarioRef::of(&scenario),
            seed,
            runs_per_point: args.runs,
            axes: axes.clone(),
            points: results,
        })
    });
    let _ = std::fs::remove_dir_all(&scratch);
    let report = report?;
    if args.json {
        output::print_json(output::json::SWEEP, &SweepJson { sweep: &report })?;
    } else {
        print!("{}", report.table());
        println!("median of each segment's largest deviation over the runs; * a run failed it");
    }
    if case.verdict == Some(campaign::oracle::Verdict::Failed)
        && report.points.iter().all(|p| p.failed_runs() == 0)
    {
        output::warning(format_args!(
            "{} failed where it was recorded but fails at no point on the simulated car of car \
             profile {}: {}",
            path.display(),
            profile.name,
            super::twin::agreement_note(path, &profile)
        ));
    }
    Ok(Exit::Success)
}

/// A sweep's result as `--json` prints it (docs/json.md).
#[derive(serde::Serialize)]
struct SweepJson<'a> {
    /// The sweep's own document (`drivecheck-sweep`, docs/case-format.md).
    sweep: &'a SweepReport,
}

/// The simulator settings of a grid point.
fn sim_settings(axes: &[Axis], values: &[f64]) -> SimSettings {
    let mut settings = SimSettings::default();
    for (axis, &value) in axes.iter().zip(values) {
        if let Parameter::Sim { setting } = axis.parameter {
            match setting {
                SimSetting::UwbClampM => settings.uwb_clamp_m = Some(value),
                SimSetting::AnchorErrorM => settings.anchor_error_m = Some(value),
                SimSetting::RangeSigmaM => settings.range_sigma_m = Some(value),
            }
        }
    }
    settings
}

fn describe(axes: &[Axis], values: &[f64]) -> String {
    axes.iter()
        .zip(values)
        .map(|(a, v)| format!("{}={v}", a.parameter))
        .collect::<Vec<_>>()
        .join(", ")
}
