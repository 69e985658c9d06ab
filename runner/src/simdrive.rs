//! Driving a case on fresh simulated cars in virtual time, unrecorded, as `shrink` and `sweep`
//! do: run k with seed + k ([`Purpose::Run`]), each on a simulator of its own, optionally with
//! simulator settings changed (`sweep`'s `sim.…` parameters). The simulated car is the embedded
//! one, or with [`SimDriver::firmware`] the car's own firmware built for the host, driving the
//! same physical car in the same world (`--car sitl:TREE`).

use std::path::PathBuf;

use car_sim::SimConfig;
use scenarios::Scenario;
use thiserror::Error;
use tokio_util::sync::CancellationToken;
use trajgen::{GenerationError, Generator, Point, Strategy};

use crate::vehicle::sitl::HostFirmware;
use crate::vehicle::{ConnectError, connect_fresh, placed};
use crate::{RecordMode, ReplaySource, RunConfig, RunError, Silent, Tests, run_campaign};
use campaign::files::{Case, CaseError, ReplayOf};
use campaign::model::{Campaign, TestPlan};
use campaign::oracle::FailurePolicy;
use campaign::seed::{Purpose, derive};

/// A case that could not be driven on the simulated car.
#[derive(Debug, Error)]
pub enum SimDriveError {
    /// The scenario's generator settings are not usable (the margins a case lacks are generated).
    #[error("the scenario's generator settings")]
    Generator(#[source] Box<GenerationError>),
    /// The case's commands cannot be planned in the scenario.
    #[error("the case cannot be driven")]
    Plan(#[source] Box<CaseError>),
    /// The simulated car did not start.
    #[error(transparent)]
    Connect(Box<ConnectError>),
    /// The one-test campaign did not run to its end.
    #[error("{error} (run directory {})", dir.display())]
    Campaign {
        /// Why.
        error: Box<RunError>,
        /// Its run directory.
        dir: PathBuf,
    },
    /// A setting of the embedded simulator's own firmware model, asked of the car's own
    /// firmware.
    #[error(
        "{setting} changes the embedded simulated car's model of the firmware; the car's own \
         firmware built for the host has its own"
    )]
    SimulationOnly {
        /// The setting.
        setting: &'static str,
    },
    /// The run's case file could not be read back.
    #[error(transparent)]
    Case(Box<RunError>),
    /// The run wrote no case.
    #[error("the run wrote no case")]
    NoCase,
}

impl From<RunError> for SimDriveError {
    fn from(error: RunError) -> Self {
        SimDriveError::Case(Box::new(error))
    }
}

impl From<ConnectError> for SimDriveError {
    fn from(error: ConnectError) -> Self {
        SimDriveError::Connect(Box::new(error))
    }
}

/// Settings of the simulated car that differ from the scenario's car (simulation only).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimSettings {
    /// The UWB estimator's largest correction per range, m (the firmware's 0.2 m otherwise).
    pub uwb_clamp_m: Option<f64>,
    /// How far every anchor really stands from its surveyed position, m.
    pub anchor_error_m: Option<f64>,
    /// Standard deviation of one UWB two-way exchange, m.
    pub range_sigma_m: Option<f64>,
}

impl SimSettings {
    /// The simulator's configuration: the simulated car `sim` (a scenario's, with its profile)
    /// with `seed` and these settings. Anchor `id` is moved by `anchor_error_m` in the direction
    /// `id` × the golden angle (a direction of its own, the same for every run and value).
    fn config(&self, sim: &SimConfig, seed: u64) -> SimConfig {
        let mut config = SimConfig {
            seed,
            ..sim.clone()
        };
        if let Some(clamp) = self.uwb_clamp_m {
            config.uwb_step_clamp_m = Some(clamp as f32);
        }
        if let Some(error) = self.anchor_error_m {
            const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;
            for anchor in &mut config.world.anchors {
                let angle = f64::from(anchor.id) * GOLDEN_ANGLE;
                anchor.position =
                    anchor.position + Point::new(error * angle.cos(), error * angle.sin());
            }
        }
        if let Some(sigma) = self.range_sigma_m {
            config.radio.exchange_sigma_m = sigma;
        }
        config
    }
}

/// Drives cases on fresh embedded simulators (see the module doc).
pub struct SimDriver<'a> {
    /// The scenario.
    pub scenario: &'a Scenario,
    /// The simulated car: the scenario's, with the car profile applied.
    pub sim: SimConfig,
    /// The failure policy of the case's campaign.
    pub policy: FailurePolicy,
    /// The case driven, for the scratch `campaign.json`.
    pub of: ReplayOf,
    /// Where the scratch run directory goes (removed by the caller).
    pub scratch: PathBuf,
    /// Runs per case.
    pub runs: u32,
    /// Keep each run's recording (`scratch/run/campaign.mcap`, until the next run): what a
    /// car reports, for `calibrate`.
    pub record: bool,
    /// Seed of run 1.
    pub seed: u64,
    /// Drive every run as the case's own test (its campaign's seed for the reset and the safe
    /// stop, its index, its car's start), the seed given to [`SimDriver::drive_once`] then
    /// being the simulated car's alone; `None`: every run is test 0 of a campaign of its own
    /// with that seed.
    pub test: Option<crate::SameTest>,
    /// Cancels the runs (a signal).
    pub cancel: &'a CancellationToken,
    /// The car's own firmware built for the host, driving the simulated car's physical car
    /// (`None`: the embedded simulated car).
    pub firmware: Option<HostFirmware>,
}

impl<'a> SimDriver<'a> {
    /// A driver of `case` (read from `path`) in `scenario` on the simulated car `sim`: its
    /// failure policy, `runs` runs from `seed`, scratch run directories in `scratch`.
    pub fn new(
        (scenario, sim): (&'a Scenario, SimConfig),
        path: &std::path::Path,
        case: &Case,
        scratch: PathBuf,
        (runs, seed): (u32, u64),
        cancel: &'a CancellationToken,
    ) -> Self {
        Self {
            scenario,
            sim,
            policy: case
                .settings
                .as_ref()
                .map_or(FailurePolicy::default(), |s| s.failure_policy),
            of: ReplayOf {
                case: path.display().to_string(),
                campaign_seed: case.campaign_seed,
                test_index: case.test_index,
                verdict: case.verdict,
                no_faults: false,
            },
            scratch,
            runs,
            record: false,
            seed,
            test: None,
            cancel,
            firmware: None,
        }
    }

    /// The plan that drives `case`: its commands with proven ahead margins (missing ones
    /// generated from the seed of run 1, [`Purpose::Margins`]).
    pub fn plan(&self, case: &Case) -> Result<TestPlan, SimDriveError> {
        let generator = Generator::new(self.scenario.generator.generator_config(Strategy::Wedge))
            .map_err(|e| SimDriveError::Generator(Box::new(e)))?;
        case.replay_plan(self.scenario, &generator, self.seed, false, 0)
            .map_err(|e| SimDriveError::Plan(Box::new(e)))
    }

    /// Drives `case` `runs` times with `settings` (run k on the car [`Purpose::Rerun`] k of the
    /// case's own test, with [`SimDriver::test`]; otherwise with seed + k, [`Purpose::Run`]):
    /// each run's seed and case.
    pub async fn drive_all(
        &self,
        case: &Case,
        settings: &SimSettings,
    ) -> Result<Vec<(u64, Case)>, SimDriveError> {
        let plan = self.plan(case)?;
        let mut cases = Vec::new();
        for k in 0..self.runs {
            let run = u64::from(k);
            let seed = match self.test {
                Some(test) => derive(
                    test.campaign_seed,
                    Purpose::Rerun {
                        test_index: test.test_index,
                        run,
                    },
                ),
                None => derive(self.seed, Purpose::Run { run }),
            };
            cases.push((seed, self.drive_once(&plan, seed, settings).await?));
        }
        Ok(cases)
    }

    /// The run directory of the last run.
    pub fn run_dir(&self) -> PathBuf {
        self.scratch.join("run")
    }

    /// One run of `plan` with `seed` on a fresh simulator, unrecorded unless [`SimDriver::record`]:
    /// the case it wrote (in [`SimDriver::run_dir`]).
    pub async fn drive_once(
        &self,
        plan: &TestPlan,
        seed: u64,
        settings: &SimSettings,
    ) -> Result<Case, SimDriveError> {
        let dir = self.run_dir();
        let _ = std::fs::remove_dir_all(&dir);
        let mut config = RunConfig::new(
            Campaign {
                seed: self.test.map_or(seed, |t| t.campaign_seed),
                tests: 1,
                no_faults: false,
            },
            dir,
            match &self.firmware {
                Some(firmware) => format!("sitl:{}", firmware.executable.display()),
                None => "sim".to_owned(),
            },
        );
        config.tests = Tests::Replay(ReplaySource {
            plan: plan.clone(),
            of: self.of.clone(),
            as_test: self.test.map(|t| t.test_index),
        });
        config.policy = self.policy;
        config.record = if self.record {
            RecordMode::All
        } else {
            RecordMode::None
        };
        let config_of_car = placed(
            settings.config(&self.sim, seed),
            self.test.and_then(|t| t.start),
        );
        if self.firmware.is_some() && settings.uwb_clamp_m.is_some() {
            return Err(SimDriveError::SimulationOnly {
                setting: "sim.uwb_clamp_m",
            });
        }
        let (car, sim) = connect_fresh(&config_of_car, self.firmware.as_ref()).await?;
        let result = run_campaign(
            &car,
            self.scenario,
            &config,
            self.cancel,
            &Silent,
            Some(sim.as_ref()),
        )
        .await;
        // The simulated car stops with its view.
        drop(sim);
        let report = result.map_err(|failure| SimDriveError::Campaign {
            error: Box::new(failure.error),
            dir: config.out_dir.clone(),
        })?;
        Ok(report.cases().next().ok_or(SimDriveError::NoCase)??)
    }
}
