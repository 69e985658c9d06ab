//! `drivecheck run --cases-from DIR`: the earlier run whose cases a campaign drives again, test
//! for test, read and checked before anything is driven.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use scenarios::Scenario;

use campaign::files::{CampaignRecord, CasesFrom};
use campaign::model::{Campaign, TestPlanner};
use campaign::oracle::FailurePolicy;
use report::data::{case_files, read_record};
use runner::CasesSource;

/// An earlier run directory whose cases are to be driven.
#[derive(Debug)]
pub(super) struct CasesRun {
    /// The directory as given.
    dir: PathBuf,
    /// Its `campaign.json`.
    pub(super) record: CampaignRecord,
    /// Its case files, test 0 first.
    pub(super) files: Vec<PathBuf>,
}

impl CasesRun {
    /// Reads `dir`'s campaign record and lists its case files: they must be tests 0 to *n* − 1
    /// of a whole campaign (a shard's are not: merge the shards first).
    pub(super) fn read(dir: &Path) -> Result<Self> {
        let record = read_record(dir).with_context(|| format!("--cases-from {}", dir.display()))?;
        if let Some(shard) = record.shard {
            bail!(
                "--cases-from {}: shard {shard} of a campaign holds only some of its tests; \
                 join the shards with `drivecheck runs merge` and give the merged directory",
                dir.display()
            );
        }
        let named = case_files(dir).with_context(|| format!("--cases-from {}", dir.display()))?;
        if named.is_empty() {
            bail!(
                "--cases-from {}: no case files (case-NNN.json)",
                dir.display()
            );
        }
        let mut files = Vec::with_capacity(named.len());
        for (expected, (index, name)) in named.into_iter().enumerate() {
            if index != expected {
                bail!(
                    "--cases-from {}: has {name} but no case file for test {expected}: the \
                     cases driven are tests 0 to n − 1 of the run",
                    dir.display()
                );
            }
            files.push(dir.join(name));
        }
        if files.len() < record.settings.tests {
            crate::output::note(format_args!(
                "note: --cases-from {}: the run planned {} tests and ended {} of them; driving \
                 those {}",
                dir.display(),
                record.settings.tests,
                files.len(),
                files.len()
            ));
        }
        Ok(Self {
            dir: dir.to_owned(),
            record,
            files,
        })
    }

    /// The scenario to load when none is given: the bundled one the run names.
    pub(super) fn scenario_name(&self) -> Result<String> {
        super::case_input::bundled_scenario("--cases-from", &self.dir, &self.record.scenario.name)
    }

    /// Checks every case against `scenario` (the run's, by hash) and plans it as the campaign
    /// will, so that a case that cannot be driven is refused before the first test; the plans
    /// are not kept (each is read again when its test begins). Gives the cases to drive and the
    /// run's failure policy.
    pub(super) fn check(
        self,
        scenario: &Scenario,
        campaign: &Campaign,
    ) -> Result<(CasesSource, FailurePolicy)> {
        let hash = scenario.hash();
        match &self.record.scenario.hash {
            Some(recorded) if *recorded == hash => {}
            recorded => bail!(
                "--cases-from {}: the run drove scenario `{}` (hash {}), but scenario `{}` \
                 hashes to {hash}: the cases are not the same tests there",
                self.dir.display(),
                self.record.scenario.name,
                recorded.as_deref().unwrap_or("unknown"),
                scenario.name
            ),
        }
        let planner = TestPlanner::new(scenario).context("the scenario's campaign settings")?;
        for (test_index, path) in self.files.iter().enumerate() {
            CasesSource::plan(path, scenario, planner.generator(), campaign, test_index)
                .context("--cases-from: a case cannot be driven")?;
        }
        let of = CasesFrom {
            run: self.dir.display().to_string(),
            campaign_seed: self.record.seed,
            scenario: self.record.scenario.clone(),
            tests: self.files.len(),
        };
        Ok((
            CasesSource {
                files: self.files,
                of,
            },
            self.record.settings.failure_policy,
        ))
    }
}
