//! A campaign's recording end to end, on the embedded simulated car in virtual time: the
//! `campaign.mcap` in its run directory holds every command and its ack, every fault command and
//! its confirmation, the state samples, the oracle results of the case files and the
//! simulator's truth; the same seed records the same messages.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use campaign::files::{Case, CommandRecord};
use campaign::model::Campaign;
use car_sim::SimConfig;
use recording::{
    AckOutcome, CarCommand, CarStateRecord, CommandAck, CommandSent, FaultRecord, FaultStatus,
    OracleRecord, Recording, TestEvent, TestEventKind, Topic, TruthRecord,
};
use runner::vehicle::SimulatorView;
use runner::{RECORDING_FILE, RunConfig, RunError, Silent, run_campaign};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

const SCENARIO: &str = "parking-lot-2anchors";

/// Runs a campaign of `tests` tests with faults on the simulator; returns its virtual duration.
async fn campaign(seed: u64, tests: usize, out: &Path) -> Duration {
    let started = Instant::now();
    try_campaign(seed, tests, out).await.unwrap();
    started.elapsed()
}

async fn try_campaign(seed: u64, tests: usize, out: &Path) -> Result<(), RunError> {
    let scenario = scenarios::bundled::load(SCENARIO).unwrap().scenario;
    let sim_config = SimConfig {
        seed,
        ..SimConfig::from_scenario(&scenario)
    };
    let (car, sim) = common::sim_car(&sim_config).await;
    let campaign = Campaign {
        seed,
        tests,
        no_faults: false,
    };
    let config = RunConfig::new(campaign, out.to_owned(), "sim");
    run_campaign(
        &car,
        &scenario,
        &config,
        &CancellationToken::new(),
        &Silent,
        Some(&sim as &dyn SimulatorView),
    )
    .await
    .map(drop)
    .map_err(|failure| failure.error)
}

fn read_case(dir: &Path, test_index: usize) -> Case {
    let text = std::fs::read_to_string(dir.join(format!("case-{test_index:03}.json"))).unwrap();
    Case::from_json(&text).unwrap()
}

fn read_recording(dir: &Path) -> Recording {
    let recording = Recording::read(&dir.join(RECORDING_FILE)).unwrap();
    recording.check_format().unwrap();
    assert!(recording.is_complete(), "{:?}", recording.cut_short());
    recording
}

/// The commands with their acks, by id; every command has exactly one ack after it.
fn commands_with_acks(recording: &Recording) -> Vec<(CommandSent, CommandAck)> {
    let commands = recording.messages::<CommandSent>().unwrap();
    let mut acks: BTreeMap<u64, _> = BTreeMap::new();
    for ack in recording.messages::<CommandAck>().unwrap() {
        assert!(
            acks.insert(ack.message.id, ack).is_none(),
            "two acks for one command"
        );
    }
    assert_eq!(commands.len(), acks.len(), "a command without an ack");
    commands
        .into_iter()
        .map(|sent| {
            let ack = acks
                .remove(&sent.message.id)
                .expect("an ack for every command");
            assert_eq!(ack.message.command, sent.message.command.name());
            assert!(ack.log_time_ns >= sent.log_time_ns);
            (sent.message, ack.message)
        })
        .collect()
}

/// Every segment the case file says was driven was sent, as planned, in an acknowledged
/// AP_ADD_POINTS of its test; and the test sent one AP_ADD_POINTS per append plus the start
/// route.
fn check_segments_sent(case: &Case, commands: &[(CommandSent, CommandAck)]) {
    let test_index = case.test_index.unwrap();
    let appended: Vec<_> = commands
        .iter()
        .filter(|(sent, _)| sent.test_index == Some(test_index))
        .filter_map(|(sent, ack)| match &sent.command {
            CarCommand::AddPoints { points } | CarCommand::ReplaceRoute { points } => {
                Some((points, &ack.outcome))
            }
            _ => None,
        })
        .collect();
    let appends = case.streaming.as_ref().unwrap().appends.len();
    assert_eq!(appended.len(), appends + 1, "test {test_index}");
    assert!(!case.segments.is_empty(), "test {test_index} drove nothing");
    for result in &case.segments {
        let CommandRecord::RunSegments { points, .. } = &case.commands[result.command_index] else {
            panic!("segment {} is not a segment command", result.segment_index);
        };
        assert!(
            appended
                .iter()
                .any(|(sent, outcome)| *sent == points && **outcome == AckOutcome::Acked),
            "test {test_index} segment {}: not sent",
            result.segment_index
        );
    }
}

/// Every fault command sent is answered, as the case file planned it; the faults before every
/// driven segment were confirmed. Returns the faults confirmed.
fn check_faults(case: &Case, faults: &[FaultRecord]) -> usize {
    let test_index = case.test_index.unwrap();
    let of_test: Vec<_> = faults
        .iter()
        .filter(|f| f.test_index == test_index)
        .collect();
    for record in &of_test {
        let CommandRecord::AddFault {
            probe,
            kind,
            param,
            start,
            duration,
            ..
        } = case.commands[record.command_index]
        else {
            panic!("command {} is not a fault", record.command_index);
        };
        let f = record.fault;
        assert_eq!(
            (f.probe, f.kind, f.param, f.start, f.duration),
            (probe, kind, param, start, duration)
        );
    }
    let sent: Vec<usize> = of_test
        .iter()
        .filter(|f| f.status == FaultStatus::Sent)
        .map(|f| f.command_index)
        .collect();
    let answered: Vec<usize> = of_test
        .iter()
        .filter(|f| {
            matches!(
                f.status,
                FaultStatus::Confirmed | FaultStatus::Refused { .. }
            )
        })
        .map(|f| f.command_index)
        .collect();
    assert_eq!(
        sent, answered,
        "test {test_index}: a fault sent is answered"
    );
    let confirmed: Vec<usize> = of_test
        .iter()
        .filter(|f| f.status == FaultStatus::Confirmed)
        .map(|f| f.command_index)
        .collect();
    for result in &case.segments {
        for fault in &result.faults_preceding {
            assert!(confirmed.contains(fault), "test {test_index} fault {fault}");
        }
    }
    // Every fault confirmed is placed: where the case planned it, and in virtual time within a
    // few centimetres of that place.
    let placed: Vec<_> = of_test
        .iter()
        .filter_map(|f| match f.status {
            FaultStatus::Placed { placement } => Some(placement),
            _ => None,
        })
        .collect();
    assert_eq!(placed.len(), confirmed.len(), "test {test_index}");
    let recorded: Vec<campaign::drive::FaultPlacement> =
        case.fault_places.iter().map(|&p| p.into()).collect();
    assert_eq!(placed, recorded, "test {test_index}");
    for placement in &placed {
        let Some(CommandRecord::AddFault { at: Some(at), .. }) =
            case.commands.get(placement.command_index)
        else {
            panic!("a generated fault has a place: {placement:?}");
        };
        assert_eq!(at.segment_index, placement.segment_index);
        assert_eq!(at.along_m, placement.planned_along_m);
        let error = placement.error_m.expect("a sample came after the fault");
        assert!(error.abs() < 0.1, "test {test_index}: {placement:?}");
    }
    confirmed.len()
}

#[tokio::test(start_paused = true)]
async fn a_campaign_records_every_command_ack_fault_state_and_oracle_result() {
    let dir = tempfile::tempdir().unwrap();
    let tests = 2;
    let duration = campaign(1, tests, dir.path()).await;
    let recording = read_recording(dir.path());
    assert!(recording.metadata("drivecheck.campaign_end").is_some());
    let commands = commands_with_acks(&recording);
    let faults: Vec<FaultRecord> = recording
        .messages::<FaultRecord>()
        .unwrap()
        .into_iter()
        .map(|f| f.message)
        .collect();
    let oracle = recording.messages::<OracleRecord>().unwrap();
    let events = recording.messages::<TestEvent>().unwrap();
    let mut confirmed = 0;
    for test_index in 0..tests {
        let case = read_case(dir.path(), test_index);
        check_segments_sent(&case, &commands);
        confirmed += check_faults(&case, &faults);
        let results: Vec<_> = oracle
            .iter()
            .filter(|o| o.message.test_index == test_index)
            .map(|o| o.message.result.clone())
            .collect();
        assert_eq!(results, case.segments, "test {test_index}");
        let ended = events.iter().find_map(|e| match &e.message.event {
            TestEventKind::Ended { verdict, reason } if e.message.test_index == test_index => {
                Some((*verdict, reason.clone()))
            }
            _ => None,
        });
        assert_eq!(ended, Some((case.verdict.unwrap(), case.reason.clone())));
    }
    assert!(confirmed > 0, "no fault was confirmed: the test sees none");

    let states = recording.messages::<CarStateRecord>().unwrap();
    assert!(!states.is_empty());
    let limit = u64::try_from(duration.as_nanos()).unwrap();
    for pair in states.windows(2) {
        assert!(pair[0].log_time_ns <= pair[1].log_time_ns);
    }
    assert!(states.iter().all(|s| s.log_time_ns <= limit));
    assert!(
        states
            .iter()
            .all(|s| s.log_time_ns == s.message.received_at_ns)
    );
    assert!(recording.count(Topic::SimTruth) > 0);
    let truth = recording.messages::<TruthRecord>().unwrap();
    assert!(truth.iter().all(|t| t.log_time_ns <= limit));
}

#[tokio::test(start_paused = true)]
async fn the_same_seed_records_the_same_messages() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    campaign(5, 1, a.path()).await;
    campaign(5, 1, b.path()).await;
    let (a, b) = (read_recording(a.path()), read_recording(b.path()));
    assert!(a.message_count() > 0);
    assert_eq!(a.message_count(), b.message_count());
    for topic in Topic::ALL {
        let payloads = |r: &Recording| r.payloads(topic).map(<[u8]>::to_vec).collect::<Vec<_>>();
        assert_eq!(payloads(&a), payloads(&b), "{}", topic.name());
    }
    let times = |r: &Recording| {
        let states = r.messages::<CarStateRecord>().unwrap();
        let commands = r.messages::<CommandSent>().unwrap();
        let acks = r.messages::<CommandAck>().unwrap();
        let truth = r.messages::<TruthRecord>().unwrap();
        (
            states.iter().map(|m| m.log_time_ns).collect::<Vec<_>>(),
            commands.iter().map(|m| m.log_time_ns).collect::<Vec<_>>(),
            acks.iter().map(|m| m.log_time_ns).collect::<Vec<_>>(),
            truth.iter().map(|m| m.log_time_ns).collect::<Vec<_>>(),
        )
    };
    assert_eq!(times(&a), times(&b));
    for name in ["drivecheck.recording", "drivecheck.scenario"] {
        assert_eq!(a.metadata(name), b.metadata(name), "{name}");
    }
    // Only the campaign's wall-clock times (and the record holding them) may differ.
    let without_clock = |r: &Recording, name: &str| {
        let mut entries = r.metadata(name).unwrap().clone();
        for key in ["started_at", "ended_at", "json"] {
            entries.remove(key);
        }
        entries
    };
    for name in ["drivecheck.campaign", "drivecheck.campaign_end"] {
        assert_eq!(without_clock(&a, name), without_clock(&b, name), "{name}");
    }
}

#[tokio::test(start_paused = true)]
async fn a_recording_that_cannot_be_written_ends_the_campaign_as_an_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join(RECORDING_FILE)).unwrap();
    let result = try_campaign(1, 1, dir.path()).await;
    let Err(error) = result else {
        panic!("the campaign ran without its recording");
    };
    assert!(matches!(error, RunError::Recording(_)), "{error:?}");
    assert!(error.to_string().contains("campaign.mcap"), "{error}");
    // The run directory is still complete.
    let text = std::fs::read_to_string(dir.path().join("campaign.json")).unwrap();
    let record = campaign::files::CampaignRecord::from_json(&text).unwrap();
    assert!(record.ended_at.is_some());
}

/// A campaign's recording has the `/foxglove/…` channels in Foxglove's well-known schemas, read
/// with the `mcap` crate (drivecheck's reader) and, where it is installed, with the official
/// Python `mcap` reader (`.ci/run` installs it into a virtual environment and names its python in
/// `DRIVECHECK_PYTHON`).
#[tokio::test(start_paused = true)]
async fn the_recording_has_foxglove_channels_that_the_official_readers_read() {
    let dir = tempfile::tempdir().unwrap();
    campaign(5, 1, dir.path()).await;
    let path = dir.path().join("campaign.mcap");
    let recording = read_recording(dir.path());
    let expected = [
        ("/foxglove/area", "foxglove.SceneUpdate"),
        ("/foxglove/route", "foxglove.SceneUpdate"),
        ("/foxglove/rtk", "foxglove.PoseInFrame"),
        ("/foxglove/uwb", "foxglove.PoseInFrame"),
        ("/foxglove/log", "foxglove.Log"),
    ];
    for (topic, schema) in expected {
        let channel = recording
            .channels()
            .find(|c| c.topic == topic)
            .unwrap_or_else(|| panic!("no channel {topic}"));
        assert_eq!(channel.schema_name, schema);
        let t = Topic::from_name(topic).unwrap();
        assert!(recording.count(t) > 0, "no message on {topic}");
    }
    // Every sample's RTK position is finite here: a pose for each.
    assert_eq!(
        recording.count(Topic::FoxgloveRtk),
        recording.count(Topic::CarState)
    );
    // The official readers: JSON channels parsed, protobuf ones decoded by their schemas with
    // the mcap package's protobuf decoder (as Foxglove decodes them).
    let python = std::env::var("DRIVECHECK_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let script = r#"
import sys, json, collections
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
counts, schemas, fields = collections.Counter(), {}, {}
protobuf = DecoderFactory()
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        counts[channel.topic] += 1
        schemas[channel.topic] = schema.name
        if channel.message_encoding == "json":
            json.loads(message.data)
        else:
            decoded = protobuf.decoder_for(channel.message_encoding, schema)(message.data)
            fields[channel.topic] = sorted(d.name for d, _ in decoded.ListFields())
print(json.dumps({"counts": counts, "schemas": schemas, "fields": fields}))
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&path)
        .output();
    let Ok(out) = out else {
        skipped(&format!("{python} does not run"));
        return;
    };
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        if stderr.contains("No module named") {
            skipped(&format!("the mcap package is not installed ({python})"));
            return;
        }
        panic!("the Python mcap reader failed: {stderr}");
    }
    let read: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (topic, schema) in expected {
        assert_eq!(read["schemas"][topic], schema, "{read}");
        assert!(read["counts"][topic].as_u64().unwrap_or(0) > 0, "{read}");
    }
    // The protobuf channels decoded to their fields by name.
    assert_eq!(
        read["fields"]["/foxglove/rtk"],
        serde_json::json!(["frame_id", "pose", "timestamp"]),
        "{read}"
    );
    let state = read["fields"]["/car/state"]
        .as_array()
        .expect("/car/state decoded");
    assert!(state.contains(&serde_json::json!("deviation_m")), "{read}");
    assert!(
        read["fields"]["/sim/truth"]
            .as_array()
            .is_some_and(|f| f.contains(&serde_json::json!("heading_rad"))),
        "{read}"
    );
}

/// Says that the test skipped the official Python reader, where the user sees it: straight to
/// standard error, which the test harness does not capture. A failure instead when
/// `DRIVECHECK_REQUIRE` (which `.ci/run` sets for what it installed) names `python-mcap`.
fn skipped(why: &str) {
    let required = std::env::var("DRIVECHECK_REQUIRE").unwrap_or_default();
    assert!(
        !required.split(',').any(|r| r.trim() == "python-mcap"),
        "the Python mcap reader is required (DRIVECHECK_REQUIRE={required}) but {why}"
    );
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "skipped (python-mcap): {why}");
}
