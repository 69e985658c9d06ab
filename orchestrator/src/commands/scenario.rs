//! `drivecheck scenario import | export | check | list`.

use std::path::Path;

use anyhow::{Context, Result, bail};
use scenarios::geojson::{Crs, ReadOptions, WriteOptions};
use scenarios::{Format, Loaded, Scenario};
use serde_json::{Value, json};

use crate::cli::{CheckArgs, ExportArgs, ImportArgs, ListArgs};
use crate::exit::Exit;
use crate::output;
use crate::scenario_arg::{load_scenario, print_warnings};

/// Converts a reference XML or GeoJSON file into scenario TOML.
pub fn import(args: &ImportArgs) -> Result<Exit> {
    let loaded = match &args.anchors {
        None => import_file(args)?,
        Some(anchors) => import_with_anchors(args, anchors)?,
    };
    // A file's warnings, whatever file it is.
    print_warnings(&args.file.display().to_string(), &loaded);
    let written = write_or_print(args.out.as_deref(), args.force, &loaded.scenario.to_toml())?;
    if let Some(path) = written {
        output::note(format_args!(
            "wrote {} (scenario {}, {} warning(s))",
            path.display(),
            loaded.scenario.name,
            loaded.warnings.len()
        ));
    }
    Ok(Exit::Success)
}

/// Reads the one file to import; a GeoJSON file with `--crs` and `--origin`, and a note on how
/// its coordinates were read.
fn import_file(args: &ImportArgs) -> Result<Loaded> {
    let text = std::fs::read_to_string(&args.file).unwrap_or_default();
    let geojson = Format::detect(&args.file, &text) == Format::GeoJson;
    if !geojson && (args.crs.is_some() || args.origin.is_some()) {
        bail!(
            "--crs and --origin are for GeoJSON; {} is not (a .geojson or .json file)",
            args.file.display()
        );
    }
    let options = ReadOptions {
        crs: args.crs.map(Into::into),
        origin: args.origin,
    };
    let imported = scenarios::load_with(&args.file, &options)?;
    if geojson {
        output::note(format_args!(
            "note: {}: {}",
            args.file.display(),
            imported.note()
        ));
    }
    Ok(imported.loaded)
}

/// Reads a reference XML area and the reference XML file of its anchors.
fn import_with_anchors(args: &ImportArgs, anchors: &Path) -> Result<Loaded> {
    if args.crs.is_some() || args.origin.is_some() {
        bail!("--crs and --origin are for GeoJSON, --anchors for reference XML");
    }
    let read = |path: &Path| {
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
    };
    let (area, anchors_text) = (read(&args.file)?, read(anchors)?);
    let name = args
        .file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(scenarios::from_xml_with_anchors(
        (&area, &args.file.display().to_string()),
        (&anchors_text, &anchors.display().to_string()),
        &name,
    )?)
}

/// Writes `text` to `out` (refusing to replace a file without `force`) and returns the path, or
/// prints it on standard output.
fn write_or_print<'a>(out: Option<&'a Path>, force: bool, text: &str) -> Result<Option<&'a Path>> {
    match out {
        Some(path) if path.exists() && !force => {
            bail!(
                "--out {}: the file exists; give --force to replace it",
                path.display()
            );
        }
        Some(path) => {
            runner::atomic::write(path, text)
                .with_context(|| format!("cannot write {}", path.display()))?;
            Ok(Some(path))
        }
        None => {
            print!("{text}");
            Ok(None)
        }
    }
}

/// Writes a scenario as GeoJSON.
pub fn export(args: &ExportArgs) -> Result<Exit> {
    let loaded = load_scenario(args.scenario.name())?;
    print_warnings(args.scenario.name(), &loaded);
    let options = WriteOptions {
        crs: args.crs.map(Into::into),
        origin: args.origin,
    };
    let text = scenarios::geojson::to_geojson(&loaded.scenario, &options)?;
    if let Some(path) = write_or_print(args.out.as_deref(), args.force, &text)? {
        let crs = options.crs.unwrap_or(Crs::Wgs84);
        output::note(format_args!(
            "wrote {} (scenario {}, {})",
            path.display(),
            loaded.scenario.name,
            crs.describe()
        ));
    }
    Ok(Exit::Success)
}

/// The summary of a scenario that `check` and `list` show.
fn summary(s: &Scenario) -> Value {
    json!({
        "name": s.name,
        "description": s.description,
        "fence_vertices": s.area.fence().vertices().len(),
        "cutouts": s.area.cutouts().len(),
        "drivable_area_m2": s.area.drivable_area(),
        "anchors": s.anchors.len(),
        "hash": s.hash(),
    })
}

/// The campaign seed whose first test `scenario check` plans.
const CHECK_SEED: u64 = 0;

/// Loads and validates a scenario and plans its first test as `run` does
/// ([`runner::plan_first_test`]), printing a summary and its warnings.
pub fn check(args: &CheckArgs) -> Result<Exit> {
    let loaded = load_scenario(args.scenario.name())?;
    let s = &loaded.scenario;
    // What run does with the scenario before it drives: a scenario whose first test cannot be
    // planned is refused here too.
    runner::plan_first_test(s, CHECK_SEED).with_context(|| {
        format!(
            "{}: run would refuse it: test 0 of seed {CHECK_SEED} cannot be planned",
            loaded.source
        )
    })?;
    if args.json {
        let mut document = summary(s);
        document["source"] = json!(loaded.source);
        document["valid"] = json!(true);
        document["warnings"] = loaded
            .warnings
            .iter()
            .map(|w| json!({"field": w.field, "message": w.kind.to_string()}))
            .collect();
        output::print_json(output::json::SCENARIO_CHECK, &document)?;
        return Ok(Exit::Success);
    }
    let printed = print_warnings(args.scenario.name(), &loaded);
    // A bundled scenario's warnings are for -v (data the user cannot change): say where they are.
    let hidden = if !printed
        && !loaded.warnings.is_empty()
        && output::verbosity() == output::Verbosity::Normal
    {
        " (a bundled scenario's: -v prints them)"
    } else {
        ""
    };
    println!(
        "{}: valid; fence {} vertices, {} cutout(s), drivable {:.0} m², {} anchor(s), {} warning(s){hidden}; hash {}",
        loaded.source,
        s.area.fence().vertices().len(),
        s.area.cutouts().len(),
        s.area.drivable_area(),
        s.anchors.len(),
        loaded.warnings.len(),
        &s.hash()[..12],
    );
    Ok(Exit::Success)
}

/// Lists the bundled scenarios with a one-line summary each.
pub fn list(args: &ListArgs) -> Result<Exit> {
    let mut all = Vec::new();
    for name in scenarios::bundled::names() {
        let loaded = scenarios::bundled::load(name)?;
        let s = &loaded.scenario;
        if args.json {
            all.push(summary(s));
            continue;
        }
        println!(
            "{name:24} {:>6.0} m²  {} cutout(s)  {} anchor(s)  {}",
            s.area.drivable_area(),
            s.area.cutouts().len(),
            s.anchors.len(),
            s.description.as_deref().unwrap_or("")
        );
    }
    if args.json {
        output::print_json(output::json::SCENARIO_LIST, &json!({ "scenarios": all }))?;
    }
    Ok(Exit::Success)
}
