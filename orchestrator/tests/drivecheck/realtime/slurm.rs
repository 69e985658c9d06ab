//! The Slurm job array of `docs/scaling.md` on a real Slurm cluster: the test starts a private
//! single-node cluster (Debian's `slurm-wlm` and `munge`: its own munge key and socket, its own
//! `slurm.conf`, free ports, everything under a temporary directory), submits the documented
//! `campaign.sh` and the documented `afterany` merge job with `sbatch`, waits for them, and checks
//! that the merged run holds the unsharded run's case files, summary and messages.
//!
//! Without the packages it says it is skipped (`.ci/run` installs them when it is root with
//! apt-get); so it does when it is not root or the daemons are refused a permission, naming why.
//! With the packages and the permissions, a cluster that does not start fails the test.

use crate::common;

use std::io::Read;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{assert_same_campaign, assert_same_messages, cases, documented, path, summary, text};

const MUNGED: &str = "/usr/sbin/munged";
const MUNGEKEY: &str = "/usr/sbin/mungekey";
const SLURMCTLD: &str = "/usr/sbin/slurmctld";
const SLURMD: &str = "/usr/sbin/slurmd";
const SBATCH: &str = "/usr/bin/sbatch";
const SQUEUE: &str = "/usr/bin/squeue";
const SCONTROL: &str = "/usr/bin/scontrol";
const SCANCEL: &str = "/usr/bin/scancel";
const SINFO: &str = "/usr/bin/sinfo";

/// How long the daemons may take to show the node idle, and the jobs to end.
const START_TIMEOUT: Duration = Duration::from_secs(30);
const JOBS_TIMEOUT: Duration = Duration::from_secs(180);

/// A private Slurm cluster: munged, slurmctld and slurmd, children of the test. Dropping it
/// cancels its jobs and kills the daemons and every process that carries its `SLURM_CONF`
/// (the `slurmstepd`s and the jobs they started), on panic too.
struct Cluster {
    root: PathBuf,
    conf: PathBuf,
    host: String,
    daemons: Vec<(&'static str, Child)>,
}

/// Why a cluster did not start: outside the test's reach (skip) or not (fail).
enum NotStarted {
    Refused(String),
    Failed(String),
}

impl Cluster {
    fn log_dir(&self) -> PathBuf {
        self.root.join("log")
    }

    /// A Slurm client (`sbatch`, `squeue`, …) run against this cluster.
    fn client(&self, program: &str) -> Command {
        let mut command = Command::new(program);
        command.env("SLURM_CONF", &self.conf);
        command
    }

    fn output(&self, program: &str, args: &[&str]) -> Output {
        self.client(program)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("{program} does not run: {e}"))
    }

    /// Every file under `log/` and the jobs' `slurm-*.out` in `results`, for a failure's message.
    fn logs(&self, results: Option<&Path>) -> String {
        let mut files: Vec<PathBuf> = Vec::new();
        for dir in std::iter::once(self.log_dir()).chain(results.map(Path::to_path_buf)) {
            if let Ok(entries) = std::fs::read_dir(&dir) {
                let mut found: Vec<PathBuf> = entries
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| {
                        let name = p.file_name().unwrap().to_string_lossy();
                        dir == self.log_dir()
                            || (name.starts_with("slurm-") && name.ends_with(".out"))
                    })
                    .collect();
                found.sort();
                files.extend(found);
            }
        }
        let mut all = String::new();
        for file in files {
            let mut text = String::new();
            let _ = std::fs::File::open(&file).and_then(|mut f| f.read_to_string(&mut text));
            // The last lines say why; a daemon's log starts with what it loaded.
            let lines: Vec<&str> = text.lines().collect();
            let tail = &lines[lines.len().saturating_sub(40)..];
            all.push_str(&format!("\n--- {}\n{}\n", file.display(), tail.join("\n")));
        }
        all
    }

    /// Starts munged, then slurmctld and slurmd, and waits until the node is idle.
    fn start(root: &Path) -> Result<Cluster, NotStarted> {
        // munged wants its socket's directory open to all, its key's closed to all but root.
        std::fs::create_dir(root).unwrap();
        set_mode(root, 0o755);
        for (dir, mode) in [
            ("munge", 0o700),
            ("run", 0o755),
            ("log", 0o755),
            ("state", 0o755),
            ("spool", 0o755),
        ] {
            std::fs::create_dir(root.join(dir)).unwrap();
            set_mode(&root.join(dir), mode);
        }
        let key = root.join("munge/munge.key");
        let made = Command::new(MUNGEKEY)
            .arg("--create")
            .arg(format!("--keyfile={}", path(&key)))
            .output()
            .expect("mungekey runs");
        assert!(made.status.success(), "mungekey: {}", text(&made));
        set_mode(&key, 0o400);
        let socket = root.join("run/munge.socket");
        let host = short_hostname();
        let conf = root.join("slurm.conf");
        let mut cluster = Cluster {
            root: root.to_path_buf(),
            conf: conf.clone(),
            host: host.clone(),
            daemons: Vec::new(),
        };
        let mut munged = Command::new(MUNGED);
        munged
            .arg("--foreground")
            .arg(format!("--key-file={}", path(&key)))
            .arg(format!("--socket={}", path(&socket)))
            .arg(format!("--pid-file={}", path(&root.join("run/munged.pid"))))
            .arg(format!("--log-file={}", path(&root.join("log/munged.log"))))
            .arg(format!(
                "--seed-file={}",
                path(&root.join("munge/munged.seed"))
            ));
        cluster.spawn("munged", munged)?;
        cluster.wait_for("munged", || socket.exists())?;

        let (ctld_port, slurmd_port) = free_ports();
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        // A node that says it has more memory than it has is drained; the documented --mem=1G
        // needs a node that says it has at least that.
        let memory_mb = mem_total_kb() / 1024 * 9 / 10;
        let r = |dir: &str| path(&root.join(dir)).to_owned();
        let conf_text = format!(
            "# A single-node cluster of drivecheck's Slurm test, private to one run of it.
ClusterName=drivecheck
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket}
SlurmUser=root
SlurmdUser=root
StateSaveLocation={state}
SlurmdSpoolDir={spool}
SlurmctldPidFile={run}/slurmctld.pid
SlurmdPidFile={run}/slurmd.pid
SlurmctldLogFile={log}/slurmctld.log
SlurmdLogFile={log}/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
MailProg=/bin/true
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SwitchType=switch/none
MpiDefault=none
ReturnToService=2
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={memory_mb} State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
",
            socket = path(&socket),
            state = r("state"),
            spool = r("spool"),
            run = r("run"),
            log = r("log"),
        );
        std::fs::write(&conf, conf_text).unwrap();
        for (name, program) in [("slurmctld", SLURMCTLD), ("slurmd", SLURMD)] {
            let mut command = Command::new(program);
            command.arg("-D").arg("-f").arg(&conf);
            cluster.spawn(name, command)?;
        }
        let started = Instant::now();
        loop {
            let state = cluster.output(SINFO, &["-h", "-N", "-n", &host, "-o", "%T"]);
            if String::from_utf8_lossy(&state.stdout).trim() == "idle" {
                break;
            }
            cluster.check_alive()?;
            if started.elapsed() > START_TIMEOUT {
                let node = cluster.output(SCONTROL, &["show", "node", &host]);
                return Err(NotStarted::Failed(format!(
                    "the node is not idle after {START_TIMEOUT:?}: {}{}",
                    text(&node),
                    cluster.logs(None)
                )));
            }
            std::thread::sleep(Duration::from_millis(250));
        }
        Ok(cluster)
    }

    /// Starts daemon `name`, its output to `log/NAME.out`, `SLURM_CONF` pointing at the cluster's.
    fn spawn(&mut self, name: &'static str, mut command: Command) -> Result<(), NotStarted> {
        let out = std::fs::File::create(self.log_dir().join(format!("{name}.out"))).unwrap();
        let child = command
            .env("SLURM_CONF", &self.conf)
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .spawn()
            .map_err(|e| NotStarted::Failed(format!("{name} does not run: {e}")))?;
        self.daemons.push((name, child));
        Ok(())
    }

    /// Waits until `ready`, or says why a daemon ended.
    fn wait_for(&mut self, name: &str, ready: impl Fn() -> bool) -> Result<(), NotStarted> {
        let started = Instant::now();
        while !ready() {
            self.check_alive()?;
            if started.elapsed() > START_TIMEOUT {
                return Err(NotStarted::Failed(format!(
                    "{name} not ready after {START_TIMEOUT:?}{}",
                    self.logs(None)
                )));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Ok(())
    }

    /// A daemon that ended: refused a permission (outside the test) or failed (the test's).
    fn check_alive(&mut self) -> Result<(), NotStarted> {
        let ended = self
            .daemons
            .iter_mut()
            .find_map(|(name, child)| Some((*name, child.try_wait().unwrap()?)));
        let Some((name, status)) = ended else {
            return Ok(());
        };
        let logs = self.logs_of(name);
        let refused = logs.lines().find(|line| {
            [
                "Operation not permitted",
                "Permission denied",
                "must be root",
            ]
            .iter()
            .any(|words| line.contains(words))
        });
        Err(match refused {
            Some(line) => NotStarted::Refused(format!("{name} ended ({status}): {line}")),
            None => NotStarted::Failed(format!("{name} ended ({status}){logs}")),
        })
    }

    fn logs_of(&self, name: &str) -> String {
        let mut all = String::new();
        for file in [format!("{name}.out"), format!("{name}.log")] {
            if let Ok(text) = std::fs::read_to_string(self.log_dir().join(&file)) {
                all.push_str(&format!("\n--- {file}\n{text}"));
            }
        }
        all
    }

    /// The cluster's jobs, one line each (`scontrol -o show job`), finished ones included.
    fn jobs(&self) -> Vec<String> {
        let out = self.output(SCONTROL, &["-o", "show", "job"]);
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter(|l| l.starts_with("JobId="))
            .map(str::to_owned)
            .collect()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Jobs first, while slurmctld can still cancel them.
        if !self.daemons.is_empty() {
            let _ = self
                .client(SCANCEL)
                .args(["--quiet", "--user", "root"])
                .stderr(Stdio::null())
                .status();
        }
        for (_, child) in &mut self.daemons {
            signal("TERM", child.id());
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        for (_, child) in &mut self.daemons {
            while child.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        // slurmstepd leaves its parent: what is left of the cluster carries its SLURM_CONF.
        let mine = format!("SLURM_CONF={}", path(&self.conf));
        for _ in 0..3 {
            let left: Vec<u32> = std::fs::read_dir("/proc")
                .into_iter()
                .flatten()
                .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
                .filter(|&pid| pid != std::process::id())
                .filter(|pid| {
                    std::fs::read(format!("/proc/{pid}/environ"))
                        .is_ok_and(|env| env.split(|&b| b == 0).any(|var| var == mine.as_bytes()))
                })
                .collect();
            if left.is_empty() {
                break;
            }
            for pid in left {
                signal("KILL", pid);
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn signal(name: &str, pid: u32) {
    let _ = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .stderr(Stdio::null())
        .status();
}

fn set_mode(p: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode)).unwrap();
}

/// The machine's short hostname, as slurmd names its node.
fn short_hostname() -> String {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    name.trim().split('.').next().unwrap().to_owned()
}

/// `MemTotal` of `/proc/meminfo`, in kB.
fn mem_total_kb() -> u64 {
    let info = std::fs::read_to_string("/proc/meminfo").unwrap();
    let line = info.lines().find(|l| l.starts_with("MemTotal:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Two TCP ports free now, for slurmctld and slurmd.
fn free_ports() -> (u16, u16) {
    let a = TcpListener::bind("0.0.0.0:0").unwrap();
    let b = TcpListener::bind("0.0.0.0:0").unwrap();
    (
        a.local_addr().unwrap().port(),
        b.local_addr().unwrap().port(),
    )
}

/// The effective user id (`/proc/self/status`).
fn euid() -> u32 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("Uid:")).unwrap();
    line.split_whitespace().nth(2).unwrap().parse().unwrap()
}

/// `text` with `from` replaced by `to`; the documented text must hold `from`.
fn substitute(text: &str, from: &str, to: &str) -> String {
    assert!(
        text.contains(from),
        "docs/scaling.md's Slurm example no longer holds {from:?}: {text}"
    );
    text.replace(from, to)
}

/// A field (`NAME=value`) of a `scontrol -o show job` line.
fn field<'a>(job: &'a str, name: &str) -> &'a str {
    job.split_whitespace()
        .find_map(|f| f.strip_prefix(name)?.strip_prefix('='))
        .unwrap_or("")
}

#[test]
fn the_slurm_job_array_runs_on_a_slurm_cluster_and_its_merge_is_the_unsharded_run() {
    let missing: Vec<&str> = [
        MUNGED, MUNGEKEY, SLURMCTLD, SLURMD, SBATCH, SQUEUE, SCONTROL, SCANCEL, SINFO,
    ]
    .into_iter()
    .filter(|p| !Path::new(p).exists())
    .collect();
    if !missing.is_empty() {
        common::skipped(
            "slurm",
            &format!(
                "{} not installed (apt-get install slurm-wlm munge)",
                missing.join(", ")
            ),
        );
        return;
    }
    if euid() != 0 {
        common::skipped(
            "slurm",
            "the Slurm cluster did not start: the test is not root, and its slurmd runs jobs \
             as root (SlurmdUser=root)",
        );
        return;
    }
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    set_mode(dir.path(), 0o755);
    let cluster = match Cluster::start(&dir.path().join("cluster")) {
        Ok(cluster) => cluster,
        Err(NotStarted::Refused(reason)) => {
            common::skipped(
                "slurm",
                &format!("the Slurm cluster did not start: {reason}"),
            );
            return;
        }
        Err(NotStarted::Failed(reason)) => panic!("the Slurm cluster did not start: {reason}"),
    };
    let version = cluster.output(SINFO, &["--version"]);
    eprintln!(
        "{} up, node {} idle after {:.1} s",
        String::from_utf8_lossy(&version.stdout).trim(),
        cluster.host,
        started.elapsed().as_secs_f64()
    );

    // The documented script and submit lines, for a 6-test campaign in 3 shards. The results
    // directory is the documented "$HOME/drivecheck-results", HOME a directory of the test.
    let home = dir.path().join("home");
    let results = home.join("drivecheck-results");
    std::fs::create_dir_all(&results).unwrap();
    let script = documented("slurm-script");
    let script = substitute(&script, "#SBATCH --array=1-20", "#SBATCH --array=1-3");
    let script = substitute(
        &script,
        "export SEED=7 TESTS=10000",
        "export SEED=9 TESTS=6",
    );
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let script = if cpus < 2 {
        substitute(&script, "--cpus-per-task=2", "--cpus-per-task=1")
    } else {
        script
    };
    std::fs::write(results.join("campaign.sh"), &script).unwrap();
    let submit = documented("slurm-submit");
    assert!(submit.contains("--dependency=afterany:"), "{submit}");

    // sbatch hands the submitter's environment to the jobs: the drivecheck under test first on
    // PATH, HOME the test's.
    let path_var = common::path_with_drivecheck();
    let submitted = cluster
        .client("sh")
        .arg("-c")
        .arg(&submit)
        .current_dir(&results)
        .env("PATH", &path_var)
        .env("HOME", &home)
        .output()
        .unwrap();
    assert!(
        submitted.status.success(),
        "{submit}: {}{}",
        text(&submitted),
        cluster.logs(Some(&results))
    );
    eprintln!(
        "submitted: {}",
        String::from_utf8_lossy(&submitted.stdout).trim()
    );

    // The cluster is the test's own: its queue holds these jobs only.
    let waiting = Instant::now();
    loop {
        let queue = cluster.output(SQUEUE, &["-h", "-o", "%i %T %r"]);
        assert!(queue.status.success(), "squeue: {}", text(&queue));
        let queue = String::from_utf8_lossy(&queue.stdout).trim().to_owned();
        if queue.is_empty() {
            break;
        }
        if waiting.elapsed() > JOBS_TIMEOUT {
            panic!(
                "the jobs did not end in {JOBS_TIMEOUT:?}; squeue:\n{queue}\njobs:\n{}\n{}",
                cluster.jobs().join("\n"),
                cluster.logs(Some(&results))
            );
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let jobs = cluster.jobs();
    eprintln!(
        "jobs ended after {:.1} s:\n{}",
        waiting.elapsed().as_secs_f64(),
        jobs.iter()
            .map(|j| format!(
                "  {} (array {} task {}) {} {} exit {}",
                field(j, "JobId"),
                field(j, "ArrayJobId"),
                field(j, "ArrayTaskId"),
                field(j, "JobName"),
                field(j, "JobState"),
                field(j, "ExitCode")
            ))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let explain = || format!("{}\n{}", jobs.join("\n"), cluster.logs(Some(&results)));
    // Three array tasks (exit status 1 is a shard whose tests failed) and the merge.
    let tasks: Vec<&String> = jobs
        .iter()
        .filter(|j| !field(j, "ArrayTaskId").is_empty())
        .collect();
    assert_eq!(tasks.len(), 3, "{}", explain());
    for task in &tasks {
        assert!(
            matches!(field(task, "ExitCode"), "0:0" | "1:0"),
            "{}",
            explain()
        );
    }
    let merge: Vec<&String> = jobs
        .iter()
        .filter(|j| field(j, "JobName") == "wrap")
        .collect();
    assert_eq!(merge.len(), 1, "{}", explain());
    assert_eq!(field(merge[0], "JobState"), "COMPLETED", "{}", explain());
    assert_eq!(field(merge[0], "ExitCode"), "0:0", "{}", explain());
    // afterany: the merge started when the last task had ended (ISO times compare as text).
    let last_end = tasks.iter().map(|t| field(t, "EndTime")).max().unwrap();
    assert!(
        field(merge[0], "StartTime") >= last_end,
        "the merge started before the array ended: {}",
        explain()
    );
    for k in 1..=3 {
        assert!(
            !cases(&results.join(format!("shard-{k}"))).is_empty(),
            "shard-{k} holds no case: {}",
            explain()
        );
    }

    // The same campaign unsharded, as scaling.rs runs it.
    let serial = dir.path().join("serial");
    let out = common::drivecheck(&[
        "run",
        "--seed",
        "9",
        "--tests",
        "6",
        "--record",
        "failing",
        "--out",
        path(&serial),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let merged = results.join("merged");
    assert!(merged.join("campaign.json").is_file(), "{}", explain());
    assert_same_campaign(&serial, &merged);
    assert_same_messages(&serial, &merged);
    assert_eq!(cases(&merged).len(), 6);
    let summary = summary(&merged);
    eprintln!(
        "merged: {} passed, {} failed of {}, as the unsharded run; {:.1} s in all",
        summary["passed"],
        summary["failed"],
        summary["tests"],
        started.elapsed().as_secs_f64()
    );
}
