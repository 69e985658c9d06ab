//! `drivecheck-dev bench kill-resume`: a campaign killed (`kill -9`) at random moments and
//! resumed each time gives exactly the uninterrupted run — its case files byte for byte, its
//! summary, and its recording's messages (topic, log time and bytes) — counted over many kills
//! (#51's acceptance: 50 random moments of a 30-test campaign).
//!
//! One uninterrupted campaign first, timed; then for each kill a campaign of the same seed into
//! a directory of its own, killed once a random number of its tests have their case files and a
//! random share of one test's time later (seeded), and `run --resume` until it ends. Each step is a `drivecheck` process
//! (`drivecheck-dev exec`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;
use orchestrator::seed::rng;
use rand::RngExt;

use crate::cli::BenchKillResumeArgs;

/// What one kill gave.
#[derive(Debug, Default)]
struct Tally {
    /// The campaign ended before the kill came.
    ended_first: usize,
    /// Killed before it had made its run directory: nothing to resume.
    before_directory: usize,
    /// Killed and resumed to the end.
    resumed: usize,
    /// Of those, the same case files, summary and recording messages as the uninterrupted run.
    identical: usize,
    /// What differed, by kill.
    differences: Vec<String>,
    /// Resumes it took in all.
    resumes: usize,
}

/// Kills, resumes and compares; prints the counts. Exit status 0 when every resumed campaign is
/// the uninterrupted one, 1 when one is not.
pub fn run(args: &BenchKillResumeArgs) -> Result<Exit> {
    let exe = std::env::current_exe().context("cannot find the drivecheck-dev executable")?;
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "kill-resume")?;
    let campaign = |out: &Path| -> Vec<String> {
        let mut a: Vec<String> = ["-q", "run", "--seed"].map(String::from).to_vec();
        a.extend([
            args.seed.to_string(),
            "--tests".into(),
            args.tests.to_string(),
            "--jobs".into(),
            args.jobs.to_string(),
            "--out".into(),
            out.display().to_string(),
        ]);
        a
    };
    let whole = root.join("whole");
    let started = Instant::now();
    let code = exec(&exe, &campaign(&whole))?;
    let took = started.elapsed();
    if !matches!(code, Some(0 | 1)) {
        bail!("the uninterrupted campaign ended with {code:?}");
    }
    let expected = RunContents::read(&whole)?;
    println!(
        "bench kill-resume: seed {}, {} tests, --jobs {}; the uninterrupted campaign took {:.2} s; \
         {} kills, each after a random number of its tests and a random part of the next",
        args.seed,
        args.tests,
        args.jobs,
        took.as_secs_f64(),
        args.kills
    );
    let mut rng = rng(args.seed);
    let mut tally = Tally::default();
    for k in 0..args.kills {
        // A moment in the campaign's own progress, whatever the machine's load: once test
        // `cases` has its case file, after a further random share of one test's time.
        let cases = rng.random_range(0..args.tests);
        let jitter = took.mul_f64(rng.random_range(0.0..1.0) / args.tests as f64);
        let out = root.join(format!("cut-{k:03}"));
        let mut child = Command::new(&exe)
            .arg("exec")
            .args(campaign(&out))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {}", exe.display()))?;
        let began = Instant::now();
        while child.try_wait()?.is_none() && case_files(&out) < cases {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        std::thread::sleep(jitter);
        let after = began.elapsed();
        if child.try_wait()?.is_some() {
            tally.ended_first += 1;
            continue;
        }
        child.kill()?;
        child.wait()?;
        if !out.join(runner::CAMPAIGN_FILE).exists() {
            tally.before_directory += 1;
            continue;
        }
        let resume = [
            "-q".to_owned(),
            "run".into(),
            "--resume".into(),
            out.display().to_string(),
        ];
        let mut ended = false;
        let mut said = String::new();
        for _ in 0..3 {
            tally.resumes += 1;
            let (code, stderr) = exec_saying(&exe, &resume)?;
            // Killed after it wrote the campaign's end: complete, nothing to drive.
            if matches!(code, Some(0 | 1)) || stderr.contains("nothing to resume") {
                ended = true;
                break;
            }
            said = stderr;
        }
        if !ended {
            tally.differences.push(format!(
                "kill {k} after {after:?}: the resume never ended: {}",
                said.trim()
            ));
            continue;
        }
        tally.resumed += 1;
        match RunContents::read(&out)?.difference(&expected) {
            None => tally.identical += 1,
            Some(what) => tally
                .differences
                .push(format!("kill {k} after {after:?}: {what}")),
        }
        if args.scratch.is_none() {
            let _ = std::fs::remove_dir_all(&out);
        }
    }
    println!(
        "| kills | ended before the kill | killed before its directory | resumed | identical | resumes run |"
    );
    println!("|---|---|---|---|---|---|");
    println!(
        "| {} | {} | {} | {} | {} | {} |",
        args.kills,
        tally.ended_first,
        tally.before_directory,
        tally.resumed,
        tally.identical,
        tally.resumes
    );
    for difference in &tally.differences {
        println!("differs: {difference}");
    }
    Ok(if tally.differences.is_empty() {
        Exit::Success
    } else {
        Exit::Found
    })
}

/// How many case files (not partials) `dir` holds now.
fn case_files(dir: &Path) -> usize {
    runner::store::RunStore::new(dir)
        .case_files()
        .map_or(0, |files| files.len())
}

/// Runs `drivecheck ARGS`, its output discarded; its exit code (`None`: killed by a signal).
fn exec(exe: &Path, args: &[String]) -> Result<Option<i32>> {
    let status = Command::new(exe)
        .arg("exec")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    Ok(status.code())
}

/// Runs `drivecheck ARGS`; its exit code and standard error.
fn exec_saying(exe: &Path, args: &[String]) -> Result<(Option<i32>, String)> {
    let output = Command::new(exe)
        .arg("exec")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    Ok((
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    ))
}

/// What a finished run directory holds that a resume must reproduce.
struct RunContents {
    dir: PathBuf,
    /// `case-NNN.json` (not the partials), by name.
    cases: BTreeMap<String, Vec<u8>>,
    /// `campaign.json`'s summary.
    summary: serde_json::Value,
    /// The recording's messages: topic, log time, bytes, in file order.
    messages: Vec<(String, u64, Vec<u8>)>,
}

impl RunContents {
    fn read(dir: &Path) -> Result<Self> {
        let mut cases = BTreeMap::new();
        for entry in
            std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?
        {
            let name = entry?.file_name().to_string_lossy().into_owned();
            if name.starts_with("case-") && name.ends_with(".json") && !name.contains(".partial-") {
                cases.insert(name.clone(), std::fs::read(dir.join(&name))?);
            }
        }
        let record_path = dir.join(runner::CAMPAIGN_FILE);
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(&record_path)
                .with_context(|| format!("cannot read {}", record_path.display()))?,
        )
        .with_context(|| format!("{} is not JSON", record_path.display()))?;
        let recording = recording::Recording::read(&dir.join(runner::RECORDING_FILE))
            .with_context(|| format!("{}: the recording", dir.display()))?;
        let messages = recording
            .held()
            .into_iter()
            .map(|m| (m.topic().name().to_owned(), m.log_time(), m.data().to_vec()))
            .collect();
        Ok(Self {
            dir: dir.to_owned(),
            cases,
            summary: record["summary"].clone(),
            messages,
        })
    }

    /// The first way `self` differs from `other`, in words.
    fn difference(&self, other: &Self) -> Option<String> {
        if self.cases.keys().ne(other.cases.keys()) {
            return Some(format!(
                "{} holds other case files ({} against {})",
                self.dir.display(),
                self.cases.len(),
                other.cases.len()
            ));
        }
        if let Some(name) = self
            .cases
            .iter()
            .find(|(name, bytes)| other.cases.get(*name) != Some(bytes))
            .map(|(name, _)| name)
        {
            return Some(format!("{name} differs"));
        }
        if self.summary != other.summary {
            return Some("the summary differs".to_owned());
        }
        if self.messages != other.messages {
            let first = self
                .messages
                .iter()
                .zip(&other.messages)
                .position(|(a, b)| a != b);
            return Some(format!(
                "the recording differs: {} messages against {}, first difference at {}",
                self.messages.len(),
                other.messages.len(),
                first.map_or_else(|| "the end".to_owned(), |i| format!("message {i}"))
            ));
        }
        None
    }
}
