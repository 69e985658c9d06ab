//! One module per subcommand; [`run`] dispatches.

mod area;
mod calibrate;
pub(crate) mod case_input;
mod cases_from;
pub mod compare;
mod completions;
mod explain;
pub mod firmware;
mod merge;
mod progress;
mod replay;
mod report;
mod resume;
mod route;
mod route_return;
mod run;
mod runs;
mod scenario;
pub mod scratch;
mod shrink;
pub mod signals;
mod sim;
mod sweep;
mod table;
mod twin;

use anyhow::Result;

use crate::cli::{
    AreaCommand, Cli, Command, RouteCommand, ScenarioCommand, SitlCommand, TwinCommand,
};
use crate::exit::Exit;

/// Runs a parsed command line and returns the process's exit status.
pub fn run(cli: Cli) -> Result<Exit> {
    match cli.command {
        Command::Run(args) => run::run(&args),
        Command::Replay(args) => replay::replay(&args),
        Command::Shrink(args) => shrink::shrink(&args),
        Command::Sweep(args) => sweep::sweep(&args),
        Command::Runs(args) => runs::runs(&args),
        Command::Report(args) => report::report(&args),
        Command::Explain(args) => explain::explain(&args),
        Command::Compare(args) => compare::compare(&args),
        Command::Sim(args) => sim::serve(&args),
        Command::Sitl(SitlCommand::Build(args)) => firmware::build_command(&args),
        Command::Calibrate(args) => calibrate::calibrate(&args),
        Command::Twin(TwinCommand::Check(args)) => twin::check(&args),
        Command::Area(AreaCommand::Validate(args)) => area::validate(&args),
        Command::Route(RouteCommand::Generate(args)) => route::generate(&args),
        Command::Route(RouteCommand::Return(args)) => route_return::plan(&args),
        Command::Scenario(ScenarioCommand::Import(args)) => scenario::import(&args),
        Command::Scenario(ScenarioCommand::Check(args)) => scenario::check(&args),
        Command::Scenario(ScenarioCommand::Export(args)) => scenario::export(&args),
        Command::Scenario(ScenarioCommand::List(args)) => scenario::list(&args),
        Command::Completions(args) => completions::completions(&args),
        Command::Man(args) => completions::man(&args),
    }
}
