//! `drivecheck scenario import | check | list`.

use anyhow::{Context, Result};

use crate::cli::{CheckArgs, ImportArgs};
use crate::exit::Exit;
use crate::scenario_arg::{load_scenario, print_warnings};

/// Converts a reference XML file into scenario TOML.
pub fn import(args: &ImportArgs) -> Result<Exit> {
    let loaded = match &args.anchors {
        None => scenarios::load(&args.xml)?,
        Some(anchors) => {
            let read = |path: &std::path::Path| {
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))
            };
            let (area, anchors_text) = (read(&args.xml)?, read(anchors)?);
            let name = args
                .xml
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            scenarios::from_xml_with_anchors(
                (&area, &args.xml.display().to_string()),
                (&anchors_text, &anchors.display().to_string()),
                &name,
            )?
        }
    };
    print_warnings(&loaded);
    let toml = loaded.scenario.to_toml();
    match &args.output {
        Some(path) if path.exists() && !args.force => {
            anyhow::bail!(
                "-o {}: the file exists; give --force to replace it",
                path.display()
            );
        }
        Some(path) => {
            crate::atomic::write(path, &toml)
                .with_context(|| format!("cannot write {}", path.display()))?;
            eprintln!(
                "wrote {} (scenario {}, {} warning(s))",
                path.display(),
                loaded.scenario.name,
                loaded.warnings.len()
            );
        }
        None => print!("{toml}"),
    }
    Ok(Exit::Success)
}

/// Loads and validates a scenario, printing a summary and its warnings.
pub fn check(args: &CheckArgs) -> Result<Exit> {
    let loaded = load_scenario(&args.scenario)?;
    print_warnings(&loaded);
    let s = &loaded.scenario;
    println!(
        "{}: valid; fence {} vertices, {} cutout(s), drivable {:.0} m², {} anchor(s), {} warning(s); hash {}",
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
pub fn list() -> Result<Exit> {
    for name in scenarios::bundled::names() {
        let loaded = scenarios::bundled::load(name)?;
        let s = &loaded.scenario;
        println!(
            "{name:24} {:>6.0} m²  {} cutout(s)  {} anchor(s)  {}",
            s.area.drivable_area(),
            s.area.cutouts().len(),
            s.anchors.len(),
            s.description.as_deref().unwrap_or("")
        );
    }
    Ok(Exit::Success)
}
