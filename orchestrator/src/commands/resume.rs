//! `drivecheck run --resume DIR`: an interrupted campaign, read and checked before anything is
//! driven, then continued in its run directory (`docs/scaling.md`, *Long campaigns*).
//!
//! A test *ended* when its case file holds a verdict that was not cut off (aborted
//! `interrupted` or `link lost`); every other test of the plan (or of the shard) is driven.
//! Every case file is checked first, as `runs merge` checks a shard's: it holds the test its
//! name says, its verdicts agree with its statistics, and it is a case of the campaign (seed,
//! scenario, faults, settings); a case that is not is refused, naming the file. So is a
//! recording (`campaign.mcap`, `campaign.mcap.resumed`) whose metadata names another seed. A
//! cut-off test's case is kept beside it as `case-NNN.partial-K.json` (K from 1, the first name
//! free) and the test is driven again from its start. The recording of the sessions before is
//! moved aside to `campaign.mcap.resumed` and copied into the new `campaign.mcap` by the runner
//! ([`runner::ResumeSource`]); a `campaign.mcap.resumed` already there is one a resume
//! that died did not finish copying, and it is the one used.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use scenarios::Scenario;

use crate::cli::{OnFailure, RunArgs};
use crate::profile_arg::LoadedProfile;
use campaign::files::CampaignRecord;
use campaign::oracle::FailurePolicy;
use car_link::CarAddress;
use report::data::{case_files, read_case, read_record};
use runner::store::RunStore;
use runner::{ResumeSource, is_cut_off};

/// An interrupted campaign's run directory as read.
#[derive(Debug)]
pub(super) struct Resumed {
    /// The directory as given.
    pub(super) dir: PathBuf,
    /// Its `campaign.json`.
    pub(super) record: CampaignRecord,
    /// The tests that ended.
    kept: BTreeSet<usize>,
    /// The tests cut off: driven again.
    cut_off: Vec<usize>,
}

impl Resumed {
    /// Reads `dir`: its campaign record and every case file, each a test of the plan. Refuses a
    /// campaign every test of which ended.
    pub(super) fn read(dir: &Path) -> Result<Self> {
        let at = || format!("--resume {}", dir.display());
        let record = read_record(dir).with_context(at)?;
        if record.replay_of.is_some() {
            bail!(
                "--resume {}: a replay (drivecheck replay) is not resumed; replay the case again",
                dir.display()
            );
        }
        check_recordings(dir, &record)?;
        let planned: BTreeSet<usize> = match record.shard {
            Some(shard) => shard.tests(record.settings.tests).collect(),
            None => (0..record.settings.tests).collect(),
        };
        let mut kept = BTreeSet::new();
        let mut cut_off = Vec::new();
        for (index, name) in case_files(dir).with_context(at)? {
            if !planned.contains(&index) {
                bail!(
                    "--resume {}: {name} is not a test of its campaign ({} tests{})",
                    dir.display(),
                    record.settings.tests,
                    record
                        .shard
                        .map(|s| format!(", shard {s}"))
                        .unwrap_or_default()
                );
            }
            let case = read_case(dir, &name).with_context(at)?;
            check_case(&record, &case, index)
                .with_context(|| format!("--resume {}: {name}", dir.display()))?;
            if is_cut_off(&case) {
                cut_off.push(index);
            } else {
                kept.insert(index);
            }
        }
        // Every test ended: nothing to resume, unless the process died before it wrote the
        // campaign's end (then the resume only completes the run directory and its recording).
        if cut_off.is_empty() && kept.len() == planned.len() && record.ended_at.is_some() {
            bail!(
                "--resume {}: nothing to resume: every one of its {} tests ended",
                dir.display(),
                planned.len()
            );
        }
        Ok(Self {
            dir: dir.to_owned(),
            record,
            kept,
            cut_off,
        })
    }

    /// The scenario to load when none is given: the bundled one the campaign names.
    pub(super) fn scenario_name(&self) -> Result<String> {
        super::case_input::bundled_scenario("--resume", &self.dir, &self.record.scenario.name)
    }

    /// Refuses a setting given on the command line that differs from the campaign's, naming it:
    /// the scenario (by hash), the seed, the number of tests, `--no-faults`, the shard, the
    /// failure policy and the car profile. `scenario_given`: the scenario came from
    /// `--scenario`, not from the bundled one the campaign names.
    pub(super) fn check(
        &self,
        args: &RunArgs,
        scenario: &Scenario,
        scenario_given: bool,
        profile: &LoadedProfile,
        firmware: Option<&super::firmware::HostFirmware>,
        cars: &[CarAddress],
    ) -> Result<()> {
        let r = &self.record;
        let dir = self.dir.display();
        // A campaign goes on on the kind of car it drove: its tests on a real car and the rest
        // on the simulator (the default `--car`) would be one summary of two cars.
        let drove: Vec<&str> = if r.cars.is_empty() {
            vec![r.car.as_str()]
        } else {
            r.cars.iter().map(|c| c.address.as_str()).collect()
        };
        let kinds: Vec<CarKind> = drove.iter().map(|a| CarKind::of_label(a)).collect();
        if let Some(given) = cars.iter().find(|c| !kinds.contains(&CarKind::of(c))) {
            bail!(
                "--resume {dir}: the campaign drove {} ({}); --car {given} is {}: a resumed \
                 campaign goes on on the same kind of car (give it with --car)",
                kinds[0].words(),
                drove.join(", "),
                CarKind::of(given).words()
            );
        }
        let differs = |flag: String, campaign: String| -> anyhow::Error {
            anyhow::anyhow!(
                "--resume {dir}: {flag} differs from the campaign's {campaign}; a resumed \
                 campaign keeps its plan and settings (leave {} out)",
                flag.split(' ').next().unwrap_or(&flag)
            )
        };
        let hash = scenario.hash();
        let recorded = r.scenario.hash.as_deref().unwrap_or("unrecorded");
        let differs_in = r.scenario.hash.as_deref().is_some_and(|h| h != hash);
        if differs_in && !scenario_given {
            // No --scenario: the bundled one of the campaign's name, which is not what it
            // drove (a file of the same name, or another version of drivecheck's).
            bail!(
                "--resume {dir}: the campaign drove scenario `{}` (hash {recorded}), not the \
                 bundled `{}` (hash {hash}): give the file it drove with --scenario",
                r.scenario.name,
                scenario.name
            );
        }
        if differs_in || r.scenario.name != scenario.name {
            return Err(differs(
                format!("--scenario {} (hash {hash})", scenario.name),
                format!("scenario `{}` (hash {recorded})", r.scenario.name),
            ));
        }
        if let Some(seed) = args.seed.filter(|&s| s != r.seed) {
            return Err(differs(
                format!("--seed {seed}"),
                format!("seed {}", r.seed),
            ));
        }
        if let Some(tests) = args.tests.filter(|&t| t != r.settings.tests) {
            return Err(differs(
                format!("--tests {tests}"),
                format!("{} tests", r.settings.tests),
            ));
        }
        if args.no_faults && !r.no_faults {
            return Err(differs(
                "--no-faults".to_owned(),
                "tests with their faults".to_owned(),
            ));
        }
        if args.shard.is_some() && args.shard != r.shard {
            return Err(differs(
                format!(
                    "--shard {}",
                    args.shard.map(|s| s.to_string()).unwrap_or_default()
                ),
                r.shard
                    .map_or("whole campaign".to_owned(), |s| format!("shard {s}")),
            ));
        }
        if let Some(given) = args.on_failure {
            let policy = match given {
                OnFailure::Stop => FailurePolicy::StopAtFailingSegment,
                OnFailure::Continue => FailurePolicy::ContinueAndRecord,
            };
            if policy != r.settings.failure_policy {
                return Err(differs(
                    format!("--on-failure {}", policy_name(policy)),
                    format!("--on-failure {}", policy_name(r.settings.failure_policy)),
                ));
            }
        }
        // The firmware a campaign drove is its tree as it was: a changed tree is another
        // firmware, and its tests are not the same campaign's.
        if let (Some(recorded), Some(given)) = (&r.car_firmware_tree_hash, firmware)
            && given.tree_hash != *recorded
        {
            bail!(
                "--resume {dir}: the campaign drove the firmware tree with hash {}, and {} \
                 now hashes to {}: resume on the tree as it was (or start another campaign)",
                report::data::short(recorded),
                r.car,
                report::data::short(&given.tree_hash)
            );
        }
        if let Some(recorded) = &r.car_profile {
            let given = profile.reference();
            if given.hash != recorded.hash {
                bail!(
                    "--resume {dir}: the campaign's simulated car is the profile {} (hash {}), \
                     this one is {} (hash {}): give the campaign's with --profile",
                    recorded.name,
                    recorded.hash,
                    given.name,
                    given.hash
                );
            }
        }
        Ok(())
    }

    /// The tests to drive: how many and which, in words.
    pub(super) fn describe(&self) -> String {
        let planned = match self.record.shard {
            Some(shard) => shard.tests(self.record.settings.tests).count(),
            None => self.record.settings.tests,
        };
        format!(
            "resuming {}: {} of {planned} tests ended{}",
            self.dir.display(),
            self.kept.len(),
            if self.cut_off.is_empty() {
                String::new()
            } else {
                format!(
                    "; driving again the test(s) cut off: {}",
                    self.cut_off
                        .iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        )
    }

    /// Moves the cut-off tests' cases to their partial names and, when this session `records`,
    /// the recording of the sessions before aside (without a recording of its own, `--record
    /// none`, `campaign.mcap` stays as the sessions before left it), and gives what the runner
    /// continues from. Nothing is driven yet.
    pub(super) fn prepare(self, records: bool) -> Result<ResumeSource> {
        let store = RunStore::new(&self.dir);
        let mut earlier: Vec<usize> = self.kept.iter().copied().collect();
        for &test in &self.cut_off {
            let from = store.case(test);
            let mut k = 1;
            let mut to = store.partial(test, k);
            while to.exists() {
                k += 1;
                to = store.partial(test, k);
            }
            std::fs::rename(&from, &to)
                .with_context(|| format!("cannot keep {} as {}", from.display(), to.display()))?;
            earlier.push(test);
        }
        earlier.sort_unstable();
        let recording = store.recording();
        let prior = store.prior_recording();
        let prior_recording = if !records {
            None
        } else if prior.exists() {
            // A resume that died while copying: its campaign.mcap is the partial copy.
            if recording.exists() {
                std::fs::remove_file(&recording)
                    .with_context(|| format!("cannot remove {}", recording.display()))?;
            }
            Some(prior)
        } else if recording.exists() {
            std::fs::rename(&recording, &prior)
                .with_context(|| format!("cannot move {} aside", recording.display()))?;
            Some(prior)
        } else {
            None
        };
        Ok(ResumeSource {
            record: self.record,
            kept: self.kept,
            earlier,
            prior_recording,
        })
    }
}

/// Nothing a case file says is taken on trust, as `runs merge` takes none: it must hold test
/// `index` (the test its name says), its values and verdicts must agree with its own statistics
/// ([`campaign::files::Case::check`]), and it must be a case of `record`'s campaign (its seed,
/// scenario, faults and settings: [`CampaignRecord::foreign`]). Another campaign's case copied
/// What kind of car drove a campaign: a resumed campaign goes on on the same kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CarKind {
    /// The embedded simulated car.
    Simulated,
    /// The car's own firmware built for the host.
    Firmware,
    /// A car (or a HIL board, or `drivecheck sim`) behind a link.
    Linked,
}

impl CarKind {
    fn of(address: &CarAddress) -> Self {
        match address {
            CarAddress::Sim => Self::Simulated,
            CarAddress::Sitl { .. } => Self::Firmware,
            _ => Self::Linked,
        }
    }

    /// The kind of a car as `campaign.json` names it (`sim`, `sitl:TREE`, `tcp://…`).
    fn of_label(label: &str) -> Self {
        label
            .parse::<CarAddress>()
            .map_or(Self::Linked, |address| Self::of(&address))
    }

    fn words(self) -> &'static str {
        match self {
            Self::Simulated => "the embedded simulated car",
            Self::Firmware => "the car's own firmware built for the host",
            Self::Linked => "a car behind a link",
        }
    }
}

/// in, a case copied under another test's name, or an edited verdict would otherwise count as a
/// test that ended.
fn check_case(record: &CampaignRecord, case: &campaign::files::Case, index: usize) -> Result<()> {
    if case.test_index != Some(index) {
        bail!(
            "holds test {}, not test {index}: a case copied under another test's name is not \
             resumed",
            case.test_index
                .map_or_else(|| "none".to_owned(), |t| t.to_string())
        );
    }
    case.check()?;
    if let Some(difference) = record.foreign(case) {
        bail!("not a case of the campaign of campaign.json: {difference}");
    }
    Ok(())
}

/// The recordings a resume continues (`campaign.mcap`, and `campaign.mcap.resumed` that a resume
/// which died left) must be of the campaign of `record`: the seed in their `drivecheck.campaign`
/// metadata is its seed. Another campaign's recording copied in is refused, naming it, before it
/// is moved, copied or removed.
fn check_recordings(dir: &Path, record: &CampaignRecord) -> Result<()> {
    let store = RunStore::new(dir);
    for file in [store.recording(), store.prior_recording()] {
        if file.exists() {
            store
                .check_recording(&file, record.seed)
                .with_context(|| format!("--resume {}", dir.display()))?;
        }
    }
    Ok(())
}

fn policy_name(policy: FailurePolicy) -> &'static str {
    match policy {
        FailurePolicy::StopAtFailingSegment => "stop",
        FailurePolicy::ContinueAndRecord => "continue",
    }
}
