//! `drivecheck sim`: a simulated car served over TCP (like the reference bridge) or UDP, in real
//! time, with optional impairment of its side of the link, until Ctrl-C (or SIGTERM, SIGHUP).

use anyhow::{Context, Result};
use car_link::firmware::FirmwareVersion;
use car_sim::{LinkImpairment, SimConfig};

use crate::cli::SimArgs;
use crate::exit::Exit;
use crate::scenario_arg::{load_scenario, print_warnings};

/// Serves the simulated car (or the firmware built for the host) until Ctrl-C.
pub fn serve(args: &SimArgs) -> Result<Exit> {
    let firmware = firmware_of(args)?;
    let loaded = load_scenario(&args.scenario)?;
    print_warnings(&args.scenario, &loaded);
    let config = sim_config(args, &loaded.scenario)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    match firmware {
        Some(firmware) => runtime.block_on(serve_firmware(args, &config, &firmware))?,
        None => runtime.block_on(serve_until_ctrl_c(args, &config))?,
    }
    Ok(Exit::Success)
}

/// `--car`: the embedded simulated car (`None`) or the firmware built for the host, with what
/// it cannot be given refused.
fn firmware_of(args: &SimArgs) -> Result<Option<super::firmware::HostFirmware>> {
    let address: car_link::CarAddress = args
        .car
        .parse()
        .with_context(|| format!("--car {}", args.car))?;
    let tree = match address {
        car_link::CarAddress::Sim => return Ok(None),
        car_link::CarAddress::Sitl { tree } => tree,
        _ => anyhow::bail!(
            "--car {}: drivecheck sim serves `sim` (the embedded simulated car) or `sitl:TREE` \
             (the car's own firmware built for the host)",
            args.car
        ),
    };
    let refused = [
        ("--udp", args.udp),
        ("--firmware", args.firmware.is_some()),
        ("--link-latency", args.link_latency.is_some()),
        ("--link-jitter", args.link_jitter.is_some()),
        ("--link-loss", args.link_loss.is_some()),
    ];
    if let Some((flag, _)) = refused.iter().find(|(_, given)| *given) {
        anyhow::bail!(
            "{flag}: not with --car sitl:TREE (the firmware is served over TCP as a car's bridge \
             serves its USB link, and the tree says which firmware it is)"
        );
    }
    super::firmware::build(&tree).map(Some)
}

/// Serves the firmware built for the host over TCP, in real time, until Ctrl-C (or the
/// firmware stops: an error).
async fn serve_firmware(
    args: &SimArgs,
    config: &SimConfig,
    firmware: &super::firmware::HostFirmware,
) -> Result<()> {
    let listener = tokio::net::TcpListener::bind(args.listen)
        .await
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    let address = listener.local_addr().unwrap_or(args.listen);
    let car = runner::vehicle::sitl::SitlCar {
        executable: firmware.executable.clone(),
        plant: runner::vehicle::sitl::plant_options(firmware, config),
    };
    let mut signals = super::signals::subscribe();
    if let Some(file) = &args.address_file {
        runner::atomic::write(file, format!("tcp://{address}\n"))
            .with_context(|| format!("cannot write {}", file.display()))?;
    }
    crate::output::note(format_args!(
        "the firmware {} built for the host, in the simulated car's world (seed {}), at \
         tcp://{address} in real time; Ctrl-C stops it",
        firmware.version, config.seed
    ));
    tokio::select! {
        served = runner::vehicle::sitl::serve_sitl_tcp(&car, listener) => {
            let why = served?;
            anyhow::bail!("the firmware built for the host stopped: {why}")
        }
        _ = signals.recv() => Ok(()),
    }
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
