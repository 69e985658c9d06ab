//! `drivecheck sim`: a simulated car served over TCP (like the reference bridge) or UDP, in real
//! time, with optional impairment of its side of the link, until Ctrl-C (or SIGTERM, SIGHUP).

use anyhow::{Context, Result};
use car_link::firmware::FirmwareVersion;
use car_sim::{LinkImpairment, SimConfig};

use crate::cli::SimArgs;
use crate::exit::Exit;
use crate::scenario_arg::{load_scenario, print_warnings};

/// Serves the simulated car until Ctrl-C.
pub fn serve(args: &SimArgs) -> Result<Exit> {
    let loaded = load_scenario(&args.scenario)?;
    print_warnings(&args.scenario, &loaded);
    let config = sim_config(args, &loaded.scenario)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    runtime.block_on(serve_until_ctrl_c(args, &config))?;
    Ok(Exit::Success)
}

fn sim_config(args: &SimArgs, scenario: &scenarios::Scenario) -> Result<SimConfig> {
    let profile = crate::profile_arg::load(args.profile.as_deref())?;
    let car = profile.sim_config(scenario)?;
    let firmware: FirmwareVersion = match &args.firmware {
        Some(text) => {
            car_sim::simulated_firmware(text).with_context(|| format!("--firmware {text}"))?
        }
        None => car.firmware,
    };
    Ok(SimConfig {
        firmware,
        seed: args.seed,
        link: LinkImpairment {
            latency: args.link_latency.unwrap_or_default(),
            jitter: args.link_jitter.unwrap_or_default(),
            loss: args.link_loss.unwrap_or_default(),
            ..LinkImpairment::default()
        },
        idle_timeout: (!args.idle_timeout.is_zero()).then_some(args.idle_timeout),
        ..car
    })
}

async fn serve_until_ctrl_c(args: &SimArgs, config: &SimConfig) -> Result<()> {
    let sim = if args.udp {
        car_sim::serve_udp(args.listen, config).await
    } else {
        car_sim::serve_tcp(args.listen, config).await
    }
    .with_context(|| {
        format!(
            "cannot listen on {} (another simulated car there? --listen {}:0 takes any free port, \
             and --address-file tells which)",
            args.listen,
            args.listen.ip()
        )
    })?;
    let scheme = if args.udp { "udp" } else { "tcp" };
    let address = sim.local_addr().unwrap_or(args.listen);
    // The signals are this command's before the address file says the car serves: a script
    // that reads the file and then sends SIGINT or SIGTERM stops the car as Ctrl-C does.
    let mut signals = super::signals::subscribe();
    if let Some(file) = &args.address_file {
        runner::atomic::write(file, format!("{scheme}://{address}\n"))
            .with_context(|| format!("cannot write {}", file.display()))?;
    }
    let link = &config.link;
    let link = if link.latency.is_zero() && link.jitter.is_zero() && link.loss == 0.0 {
        "an ideal link (no latency, no loss)".to_owned()
    } else {
        format!(
            "latency {:.1} ms + up to {:.1} ms, loss {:.1} %",
            link.latency.as_secs_f64() * 1e3,
            link.jitter.as_secs_f64() * 1e3,
            link.loss * 100.0
        )
    };
    crate::output::note(format_args!(
        "simulated car (firmware {}, seed {}) at {scheme}://{address}; {link}; Ctrl-C stops it",
        config.firmware, config.seed,
    ));
    let _ = signals.recv().await;
    sim.shutdown();
    Ok(())
}
