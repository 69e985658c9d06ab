//! `drivecheck-dev bench twin-reach`: how near `drivecheck calibrate` brings the twin to what the
//! recordings allow (#54, `docs/twin.md`).
//!
//! Every car of the bench is a profile written the way real cars differ from the default one
//! (anchors off their surveyed places, range biases, lost exchanges, odometry scale, IMU yaw bias
//! and drift). Each is driven as "the car" (the embedded simulator with the profile, virtual
//! time) for a training campaign; its run directory is copied without any `/sim/*` channel, the
//! simulator's profile record or the case files' `car_profile`, and `calibrate` fits a profile
//! on that copy. A held-out campaign of another seed, driven on the car, is then `twin check`ed
//! on the fitted profile (the default car comes with it) and on the car's own profile: the
//! ceiling, what a fit can at best reach. Each step is a `drivecheck` process of its own.
//!
//! Per car it prints the verdict agreement and median |Δ| of each, the time calibrate took, and
//! each parameter's error in the units of #54: metres for an offset or a bias, and for the rest
//! the error divided by its tolerance times 0.05 (an odometry-scale error of 0.01, a yaw-bias
//! error of 0.5°, a yaw-drift error of 0.5°/min count as 0.05; a ranging σ, a share of lost
//! exchanges or an NLOS σ count as they are). A parameter is within tolerance at 0.1 m for an
//! offset and 0.05 for the rest.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::cli::BenchTwinReachArgs;
use campaign::files::{TwinCheck, TwinSummary};
use campaign::twin::TWIN_FILE;
use car_sim::CarProfile;
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;

/// A held-out car: its letter, what it is, its profile's TOML (without the format lines).
struct Car {
    letter: &'static str,
    what: &'static str,
    profile: &'static str,
}

/// The cars of the bench (`parking-lot-2anchors`: anchors 50 and 234), in the ranges of #54.
const CARS: [Car; 5] = [
    Car {
        letter: "F",
        what: "anchors 0.39/0.40 m off, biases +0.11/−0.07 m, 12 % lost",
        profile: "[radio]\nexchange_drop_rate = 0.12\n\
                  [anchors.\"50\"]\noffset_m = [0.30, -0.25]\nrange_bias_m = 0.11\n\
                  [anchors.\"234\"]\noffset_m = [-0.20, 0.35]\nrange_bias_m = -0.07\n",
    },
    Car {
        letter: "G",
        what: "dynamics: odometry scale 1.02, yaw bias −1.2°, drift +0.8°/min",
        profile: "[odometry]\nscale = 1.02\n[imu]\nyaw_bias_deg = -1.2\nyaw_drift_deg_per_min = 0.8\n",
    },
    Car {
        letter: "H",
        what: "radio: σ 0.13 m, 18 % lost, NLOS σ 0.25 m; anchor 50 0.22 m off, bias +0.06 m",
        profile: "[radio]\nrange_sigma_m = 0.13\nexchange_drop_rate = 0.18\nnlos_extra_sigma_m = 0.25\n\
                  [anchors.\"50\"]\noffset_m = [0.20, 0.10]\nrange_bias_m = 0.06\n",
    },
    Car {
        letter: "I",
        what: "mixed: anchors 0.39/0.40 m off, biases −0.09/+0.13 m, 8 % lost, scale 0.98, yaw +1.0°, drift −0.6°/min",
        profile: "[radio]\nexchange_drop_rate = 0.08\n\
                  [anchors.\"50\"]\noffset_m = [-0.25, 0.30]\nrange_bias_m = -0.09\n\
                  [anchors.\"234\"]\noffset_m = [0.35, 0.20]\nrange_bias_m = 0.13\n\
                  [odometry]\nscale = 0.98\n[imu]\nyaw_bias_deg = 1.0\nyaw_drift_deg_per_min = -0.6\n",
    },
    Car {
        letter: "J",
        what: "mixed: anchors 0.47/0.42 m off, biases +0.14/−0.06 m, 15 % lost, σ 0.08 m, scale 1.025, yaw −1.5°, drift +1.0°/min",
        profile: "[radio]\nrange_sigma_m = 0.08\nexchange_drop_rate = 0.15\n\
                  [anchors.\"50\"]\noffset_m = [0.40, 0.25]\nrange_bias_m = 0.14\n\
                  [anchors.\"234\"]\noffset_m = [-0.30, -0.30]\nrange_bias_m = -0.06\n\
                  [odometry]\nscale = 1.025\n[imu]\nyaw_bias_deg = -1.5\nyaw_drift_deg_per_min = 1.0\n",
    },
];

/// The scenario of the bench.
const SCENARIO: &str = "parking-lot-2anchors";

/// One parameter's error: its name, the error in #54's units, and whether calibrate fitted it
/// and called it identified (from the fitted profile's header).
struct ParameterError {
    name: String,
    error: f64,
    tolerance: f64,
    fitted: bool,
    identified: bool,
}

/// Measures and prints the table.
pub fn run(args: &BenchTwinReachArgs) -> Result<Exit> {
    let exe = std::env::current_exe().context("cannot find the drivecheck-dev executable")?;
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "twin-reach")?;
    let cars: Vec<&Car> = CARS
        .iter()
        .filter(|c| args.cars.is_empty() || args.cars.iter().any(|l| l == c.letter))
        .collect();
    if cars.is_empty() {
        bail!(
            "--cars {}: no such car (the bench's: {})",
            args.cars.join(","),
            CARS.map(|c| c.letter).join(",")
        );
    }
    println!(
        "bench twin-reach on {SCENARIO}: per car a {}-test campaign (seed {}) driven on the car, \
         stripped of /sim/* and the profile, calibrated on (calibrate {}); twin check --runs {} \
         of a held-out {}-test campaign (seed {})\n",
        args.tests,
        args.seed,
        if args.calibrate.is_empty() {
            "with its defaults".to_owned()
        } else {
            args.calibrate.join(" ")
        },
        args.runs,
        args.held_tests,
        args.held_seed
    );
    let mut rows = Vec::new();
    for car in cars {
        let dir = root.join(format!("car-{}", car.letter));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let truth_file = dir.join("car.toml");
        let truth_text = format!(
            "format = \"drivecheck-car-profile\"\nversion = 1\n{}",
            car.profile
        );
        std::fs::write(&truth_file, &truth_text)
            .with_context(|| format!("cannot write {}", truth_file.display()))?;
        let truth = CarProfile::from_toml(&truth_text, &truth_file.display().to_string())?;

        let train = dir.join("train");
        let (tests, seed) = (args.tests.to_string(), args.seed.to_string());
        exec(
            &exe,
            &[
                "-q",
                "run",
                "--scenario",
                SCENARIO,
                "--tests",
                &tests,
                "--seed",
                &seed,
                "--profile",
                path(&truth_file)?,
                "--out",
                path(&train)?,
            ],
            &[0, 1],
            None,
        )?;
        let stripped = dir.join("train-stripped");
        strip_run(&train, &stripped)?;

        let fitted_file = dir.join("fitted.toml");
        let mut calibrate_args = vec![
            "calibrate".to_owned(),
            path(&stripped)?.to_owned(),
            "--out".to_owned(),
            path(&fitted_file)?.to_owned(),
        ];
        calibrate_args.extend(args.calibrate.iter().cloned());
        let started = Instant::now();
        let words: Vec<&str> = calibrate_args.iter().map(String::as_str).collect();
        exec(&exe, &words, &[0], Some(&dir.join("calibrate.txt")))?;
        let calibrate_s = started.elapsed().as_secs_f64();
        let fitted_text = std::fs::read_to_string(&fitted_file)
            .with_context(|| format!("cannot read {}", fitted_file.display()))?;
        let fitted = CarProfile::from_toml(&fitted_text, &fitted_file.display().to_string())?;
        let errors = parameter_errors(&truth, &fitted, &fitted_text);

        let held = dir.join("held");
        let (tests, seed) = (args.held_tests.to_string(), args.held_seed.to_string());
        exec(
            &exe,
            &[
                "-q",
                "run",
                "--scenario",
                SCENARIO,
                "--tests",
                &tests,
                "--seed",
                &seed,
                "--profile",
                path(&truth_file)?,
                "--record",
                "none",
                "--out",
                path(&held)?,
            ],
            &[0, 1],
            None,
        )?;
        let runs = args.runs.to_string();
        let check = |profile: &Path| -> Result<TwinCheck> {
            exec(
                &exe,
                &[
                    "-q",
                    "twin",
                    "check",
                    path(&held)?,
                    "--profile",
                    path(profile)?,
                    "--runs",
                    &runs,
                ],
                &[0],
                None,
            )?;
            let file = held.join(TWIN_FILE);
            let text = std::fs::read_to_string(&file)
                .with_context(|| format!("cannot read {}", file.display()))?;
            TwinCheck::from_json(&text).with_context(|| file.display().to_string())
        };
        let of_fit = check(&fitted_file)?;
        let of_truth = check(&truth_file)?;
        let summary = |check: &TwinCheck, k: usize| -> Result<TwinSummary> {
            check
                .profiles
                .get(k)
                .map(|p| p.summary)
                .context("the twin check has no such profile")
        };
        let row = Row {
            car,
            calibrate_s,
            evaluations: candidates_of(&dir.join("calibrate.txt")),
            fitted: summary(&of_fit, 0)?,
            default: summary(&of_fit, 1)?,
            truth: summary(&of_truth, 0)?,
            errors,
        };
        print_car(&row);
        rows.push(row);
    }
    print_table(&rows);
    Ok(Exit::Success)
}

/// One car's figures.
struct Row<'a> {
    car: &'a Car,
    calibrate_s: f64,
    evaluations: Option<String>,
    fitted: TwinSummary,
    default: TwinSummary,
    truth: TwinSummary,
    errors: Vec<ParameterError>,
}

fn share(s: &TwinSummary) -> String {
    s.verdicts_agreed
        .map_or_else(|| "-".to_owned(), |a| format!("{:.0} %", 100.0 * a))
}

fn metres(m: Option<f64>) -> String {
    m.map_or_else(|| "-".to_owned(), |m| format!("{m:.3} m"))
}

/// The worst error of the parameters `keep` keeps, with its name.
fn worst(errors: &[ParameterError], keep: impl Fn(&ParameterError) -> bool) -> String {
    errors
        .iter()
        .filter(|e| keep(e))
        .max_by(|a, b| (a.error / a.tolerance).total_cmp(&(b.error / b.tolerance)))
        .map_or_else(
            || "-".to_owned(),
            |e| {
                format!(
                    "{:.3} ({}{})",
                    e.error,
                    e.name,
                    if e.error <= e.tolerance {
                        ", within"
                    } else {
                        ", OFF"
                    }
                )
            },
        )
}

fn print_car(row: &Row) {
    println!("car {}: {}", row.car.letter, row.car.what);
    println!(
        "  calibrate: {:.0} s{}",
        row.calibrate_s,
        row.evaluations
            .as_deref()
            .map_or_else(String::new, |e| format!(", {e}"))
    );
    for (name, s) in [
        ("fitted", &row.fitted),
        ("default", &row.default),
        ("own profile", &row.truth),
    ] {
        println!(
            "  {name:>11}: {} segments, verdicts agreed {}, median |Δ| {}, p90 |Δ| {}",
            s.segments,
            share(s),
            metres(s.median_abs_delta_m),
            metres(s.p90_abs_delta_m)
        );
    }
    println!("  parameters (error in #54's units; tolerance; fitted/identified by calibrate):");
    for e in &row.errors {
        println!(
            "    {:<32} {:>6.3} (tolerance {:.2}){}{}",
            e.name,
            e.error,
            e.tolerance,
            if e.fitted { ", fitted" } else { ", kept" },
            if e.identified { ", identified" } else { "" }
        );
    }
    println!();
}

fn print_table(rows: &[Row]) {
    println!(
        "| car | calibrate | verdicts agreed: fitted / default / own profile | median |Δ|: fitted / default / own profile | worst fitted parameter | worst identified parameter |"
    );
    println!("|---|---|---|---|---|---|");
    for row in rows {
        println!(
            "| {}: {} | {:.0} s | {} / {} / {} | {} / {} / {} | {} | {} |",
            row.car.letter,
            row.car.what,
            row.calibrate_s,
            share(&row.fitted),
            share(&row.default),
            share(&row.truth),
            metres(row.fitted.median_abs_delta_m),
            metres(row.default.median_abs_delta_m),
            metres(row.truth.median_abs_delta_m),
            worst(&row.errors, |e| e.fitted),
            worst(&row.errors, |e| e.identified),
        );
    }
}

/// The "N candidates" of calibrate's last line, if it printed one.
fn candidates_of(output: &Path) -> Option<String> {
    let text = std::fs::read_to_string(output).ok()?;
    let line = text.lines().rev().find(|l| l.starts_with("written: "))?;
    let inner = line.split_once(" (")?.1;
    Some(inner.split(',').next()?.trim().to_owned())
}

/// The value calibrate's header says it fitted for `name`, and whether it called it identified
/// (`# NAME = VALUE[ ± SE]; identified: yes|no…`).
fn header_line<'a>(header: &'a str, name: &str) -> Option<&'a str> {
    header.lines().take_while(|l| l.starts_with('#')).find(|l| {
        l.strip_prefix("# ")
            .and_then(|rest| rest.strip_prefix(name))
            .is_some_and(|rest| rest.starts_with(" = "))
    })
}

/// Every parameter's error, fitted against `truth` (see the module doc for the units).
fn parameter_errors(truth: &CarProfile, fitted: &CarProfile, header: &str) -> Vec<ParameterError> {
    let mut out = Vec::new();
    let mut push = |name: String, error: f64, tolerance: f64| {
        let line = header_line(header, &name);
        out.push(ParameterError {
            fitted: line.is_some(),
            identified: line.is_some_and(|l| l.contains("; identified: yes")),
            name,
            error,
            tolerance,
        });
    };
    let bias = |p: &CarProfile, id: u8| {
        p.anchors
            .get(&id)
            .and_then(|a| a.range_bias_m)
            .unwrap_or_else(|| p.radio_model().drawn_bias(id))
    };
    let offset = |p: &CarProfile, id: u8| p.anchors.get(&id).map_or([0.0, 0.0], |a| a.offset_m);
    for id in [50u8, 234] {
        for axis in 0..2 {
            push(
                format!("anchors.\"{id}\".offset_m[{axis}]"),
                (offset(fitted, id)[axis] - offset(truth, id)[axis]).abs(),
                0.1,
            );
        }
        push(
            format!("anchors.\"{id}\".range_bias_m"),
            (bias(fitted, id) - bias(truth, id)).abs(),
            0.05,
        );
    }
    push(
        "odometry.scale".to_owned(),
        (fitted.odometry.scale - truth.odometry.scale).abs() / 0.01 * 0.05,
        0.05,
    );
    push(
        "imu.yaw_bias_deg".to_owned(),
        (fitted.imu.yaw_bias_deg - truth.imu.yaw_bias_deg).abs() / 0.5 * 0.05,
        0.05,
    );
    push(
        "imu.yaw_drift_deg_per_min".to_owned(),
        (fitted.imu.yaw_drift_deg_per_min - truth.imu.yaw_drift_deg_per_min).abs() / 0.5 * 0.05,
        0.05,
    );
    push(
        "radio.range_sigma_m".to_owned(),
        (fitted.radio.range_sigma_m - truth.radio.range_sigma_m).abs(),
        0.05,
    );
    push(
        "radio.exchange_drop_rate".to_owned(),
        (fitted.radio.exchange_drop_rate - truth.radio.exchange_drop_rate).abs(),
        0.05,
    );
    push(
        "radio.nlos_extra_sigma_m".to_owned(),
        (fitted.radio.nlos_extra_sigma_m - truth.radio.nlos_extra_sigma_m).abs(),
        0.05,
    );
    out
}

/// `drivecheck ARGS` in a process of its own (`drivecheck-dev exec`); its status must be one of
/// `ok`; its standard output goes to `stdout` (else nowhere), its standard error is shown on
/// failure.
fn exec(exe: &Path, args: &[&str], ok: &[i32], stdout: Option<&Path>) -> Result<()> {
    let out = match stdout {
        Some(file) => Stdio::from(
            std::fs::File::create(file)
                .with_context(|| format!("cannot create {}", file.display()))?,
        ),
        None => Stdio::null(),
    };
    let output = Command::new(exe)
        .arg("exec")
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(Stdio::piped())
        .output()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    match output.status.code() {
        Some(code) if ok.contains(&code) => Ok(()),
        _ => bail!(
            "drivecheck {} ended with {}: {}",
            args.join(" "),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        ),
    }
}

/// A copy of the run directory `from` in `to` with nothing of the simulator's truth: the
/// recording without its `/sim/*` channels and the `drivecheck.sim.profile` record, every JSON
/// file without its `car_profile`.
fn strip_run(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("cannot create {}", to.display()))?;
    for entry in
        std::fs::read_dir(from).with_context(|| format!("cannot read {}", from.display()))?
    {
        let file = entry?.path();
        let Some(name) = file.file_name().and_then(|n| n.to_str()).map(str::to_owned) else {
            continue;
        };
        if name == "campaign.mcap" {
            strip_recording(&file, &to.join(&name))?;
        } else if name.ends_with(".json") {
            let text = std::fs::read_to_string(&file)
                .with_context(|| format!("cannot read {}", file.display()))?;
            let mut json: serde_json::Value =
                serde_json::from_str(&text).with_context(|| file.display().to_string())?;
            if let Some(object) = json.as_object_mut() {
                object.remove("car_profile");
            }
            std::fs::write(to.join(&name), serde_json::to_string_pretty(&json)?)?;
        }
    }
    Ok(())
}

/// A copy of the recording `from` without the `/sim/*` channels and the simulator's profile
/// record, every other record in its order.
fn strip_recording(from: &Path, to: &Path) -> Result<()> {
    use std::collections::BTreeMap;
    let bytes = std::fs::read(from).with_context(|| format!("cannot read {}", from.display()))?;
    let file = std::io::BufWriter::new(
        std::fs::File::create(to).with_context(|| format!("cannot create {}", to.display()))?,
    );
    let mut writer = mcap::Writer::new(file)?;
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    for record in mcap::read::ChunkFlattener::new(&bytes)? {
        match record? {
            mcap::records::Record::Schema { header, data } => {
                let id = writer.add_schema(&header.name, &header.encoding, &data)?;
                schemas.insert(header.id, id);
            }
            mcap::records::Record::Channel(c) if !c.topic.starts_with("/sim/") => {
                let schema = *schemas.get(&c.schema_id).with_context(|| {
                    format!("{}: channel {} without its schema", from.display(), c.topic)
                })?;
                let id = writer.add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)?;
                channels.insert(c.id, id);
            }
            mcap::records::Record::Message { header, data } => {
                if let Some(&id) = channels.get(&header.channel_id) {
                    let header = mcap::records::MessageHeader {
                        channel_id: id,
                        ..header
                    };
                    writer.write_to_known_channel(&header, &data)?;
                }
            }
            mcap::records::Record::Metadata(m) if m.name != "drivecheck.sim.profile" => {
                writer.write_metadata(&m)?;
            }
            _ => {}
        }
    }
    writer.finish()?;
    Ok(())
}

fn path(p: &Path) -> Result<&str> {
    p.to_str()
        .with_context(|| format!("{}: not a UTF-8 path", p.display()))
}
