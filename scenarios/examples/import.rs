//! Converts a scenario (reference route XML or TOML) into canonical TOML on standard output.
//!
//! `cargo run -p scenarios --example import -- AREA.xml ["description"] > AREA.toml`; this is how
//! the bundled areas in `scenarios/areas/` were produced (their header comments were added after).

use std::process::ExitCode;

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: import AREA.xml [DESCRIPTION]");
        return ExitCode::from(2);
    };
    let mut loaded = match scenarios::load(&path) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    for warning in &loaded.warnings {
        eprintln!("warning: {warning}");
    }
    loaded.scenario.description = args.next();
    print!("{}", scenarios::to_toml(&loaded.scenario));
    ExitCode::SUCCESS
}
