//! Tests of the recording: every channel read back, schemas that describe the messages, and what
//! a killed or truncated recording still holds.

use std::path::Path;
use std::time::Duration;

use car_link::{CarState, StateSample};
use car_sim::{DebugEvent, FwPose, RadioPath, RangeResult, Truth};
use scenarios::Scenario;
use serde_json::Value;
use tokio::time::{Instant, advance};

use super::*;
use campaign::files::{
    CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION, CampaignRecord, Header, RoutePointRecord,
    ScenarioRef, SegmentResult, Settings,
};
use campaign::model::{Fault, FaultKind, Probe, Segment, SegmentIntent};
use campaign::oracle::{FailurePolicy, SegmentOracle, Verdict};
use campaign::safety::{Abort, AbortReason};

fn scenario() -> Scenario {
    scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario
}

fn campaign(s: &Scenario) -> CampaignRecord {
    CampaignRecord {
        header: Header::current(CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION),
        seed: 42,
        no_faults: false,
        scenario: ScenarioRef::of(s),
        settings: Settings::new(s, 3, FailurePolicy::default()),
        car: "sim".to_owned(),
        car_profile: None,
        car_firmware_version: Some("12.3".to_owned()),
        car_firmware_tree_hash: None,
        started_at: "2026-11-22T10:55:21Z".to_owned(),
        ended_at: None,
        summary: None,
        replay_of: None,
        cases_from: None,
        shard: None,
        sessions: Vec::new(),
        cars: Vec::new(),
    }
}

fn create(path: &Path, s: &Scenario, simulated: bool, origin: Instant) -> Recorder {
    let campaign = campaign(s);
    let start = RecordingStart {
        campaign: &campaign,
        scenario: s,
        origin,
        simulated,
        chunk_interval: DEFAULT_CHUNK_INTERVAL,
        live: None,
        test_spans: false,
        sim_profile: None,
    };
    Recorder::create(path, &start).unwrap()
}

/// A state sample requested at `at` and received 12 ms later.
fn sample(at: Instant, x: f64) -> StateSample {
    let state = CarState {
        px: x,
        py: 2.0,
        yaw: 90.0,
        px_uwb: x + 0.3,
        py_uwb: 2.4,
        speed: 1.2,
        ms_today: 40_000_123,
        ap_route_left: 7,
        ..CarState::default()
    };
    StateSample {
        state,
        car_id: 5,
        requested_at: at,
        received_at: at + Duration::from_millis(12),
    }
}

fn fault() -> Fault {
    Fault {
        probe: Probe::UwbRange(3),
        kind: FaultKind::Offset,
        param: 1.5,
        start: 2,
        duration: 10,
        at: None,
    }
}

fn segment() -> Segment {
    let tail = trajgen::RouteTail {
        end: trajgen::Point::new(0.0, 0.0),
        heading: 0.0,
    };
    Segment::generated_from(
        &tail,
        SegmentIntent {
            seed: 7,
            points: 2,
            speed_mps: 1.0,
        },
        vec![trajgen::Point::new(1.0, 2.0), trajgen::Point::new(2.0, 2.5)],
        vec![trajgen::Point::new(3.0, 3.0)],
    )
}

fn truth(time_ms: u64) -> Truth {
    let pose = FwPose {
        x: 1.0,
        y: 2.0,
        yaw: 90.0,
    };
    Truth {
        time_ms,
        x: 1.0,
        y: 2.0,
        heading: 0.5,
        speed: 1.0,
        steering_angle: 0.1,
        fused: pose,
        uwb: FwPose {
            x: f32::NAN,
            ..pose
        },
    }
}

fn debug_events() -> Vec<DebugEvent> {
    vec![
        DebugEvent::Range {
            at_ms: 900,
            anchor: 3,
            path: Some(RadioPath::Reflected {
                wall: 1,
                length: 12.0,
                direct: 9.0,
            }),
            true_range: Some(9.1),
            result: RangeResult::Measured(12.25),
        },
        DebugEvent::RangeFused {
            at_ms: 950,
            anchor: 3,
            range: 13.75,
            moved: true,
        },
        DebugEvent::Fault {
            at_ms: 950,
            probe: "uwb_range_3".to_owned(),
            slots: 1,
            iteration: 3,
            before: 12.25,
            after: 13.75,
        },
        DebugEvent::WatchdogExpired { at_ms: 990 },
    ]
}

fn oracle_record() -> OracleRecord {
    let mut oracle = SegmentOracle::new();
    oracle.push(trajgen::Point::new(0.4, 0.3), trajgen::Point::new(0.0, 0.0));
    OracleRecord {
        test_index: 0,
        result: SegmentResult {
            segment_index: 0,
            command_index: 1,
            faults_preceding: vec![0],
            faults_active: vec![],
            oracle: oracle.result(1.0),
        },
    }
}

/// Writes one test's worth of every channel; returns the file's bytes.
async fn record_every_channel(path: &Path, s: &Scenario) -> Vec<u8> {
    let origin = Instant::now();
    let mut recorder = create(path, s, true, origin);
    recorder
        .write(&TestEvent {
            test_index: 0,
            event: TestEventKind::Started { commands: 2 },
        })
        .unwrap();
    recorder
        .write(&PlannedReturnRoute {
            test_index: 0,
            points: vec![RoutePointRecord {
                x: -1.0,
                y: 0.0,
                speed: 0.8,
            }],
        })
        .unwrap();
    recorder
        .write(&PlannedSegment::new(0, 1, 0, &segment()))
        .unwrap();
    recorder.write(&FaultRecord::sent(0, 0, &fault())).unwrap();
    let confirmation: Result<(), String> = Ok(());
    recorder
        .write(&FaultRecord::answered(0, 0, &fault(), &confirmation))
        .unwrap();
    let points = [car_link::RoutePoint::at(1.0, 2.0, 1.0)];
    let id = recorder
        .command_sent(Some(0), CarCommand::add_points(&points))
        .unwrap();
    advance(Duration::from_millis(30)).await;
    let acked: Result<(), String> = Ok(());
    recorder.command_answered(id, &acked).unwrap();
    recorder.car_state(&sample(Instant::now(), 1.0)).unwrap();
    advance(Duration::from_millis(1000)).await;
    recorder.sim_truth(&truth(1000)).unwrap();
    recorder.sim_events(&debug_events()).unwrap();
    recorder.write(&oracle_record()).unwrap();
    let abort = Abort::new(AbortReason::RtkLost, Duration::from_millis(1030));
    recorder.write(&SafetyRecord::new(Some(0), abort)).unwrap();
    recorder
        .write(&TestEvent {
            test_index: 0,
            event: TestEventKind::Ended {
                verdict: Verdict::Aborted,
                reason: Some("RTK fix lost".to_owned()),
            },
        })
        .unwrap();
    let finished = recorder.finish().unwrap();
    // 16 on drivecheck's channels, 9 on Foxglove's: the area, the route cleared and a segment,
    // the fault sent and confirmed, the RTK and UWB poses, the safety stop and the test's end.
    assert_eq!(finished.messages, 25);
    std::fs::read(path).unwrap()
}

#[tokio::test(start_paused = true)]
async fn every_channel_reads_back_what_was_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let s = scenario();
    record_every_channel(&path, &s).await;
    let recording = Recording::read(&path).unwrap();
    assert!(recording.is_complete(), "{:?}", recording.cut_short());
    for topic in Topic::ALL {
        assert!(recording.count(topic) > 0, "no message on {topic}");
    }
    let commands = recording.messages::<CommandSent>().unwrap();
    let acks = recording.messages::<CommandAck>().unwrap();
    assert_eq!(acks[0].message.id, commands[0].message.id);
    assert_eq!(acks[0].message.outcome, AckOutcome::Acked);
    assert_eq!(acks[0].message.round_trip_ms, Some(30.0));
    assert_eq!(acks[0].log_time_ns, 30_000_000);
    let states = recording.messages::<CarStateRecord>().unwrap();
    let origin = Instant::now() - Duration::from_millis(1030);
    let at = origin + Duration::from_millis(30);
    assert_eq!(
        states[0].message,
        CarStateRecord::new(&sample(at, 1.0), origin)
    );
    assert_eq!(states[0].message.requested_at_ns, 30_000_000);
    assert_eq!(
        states[0].log_time_ns, 42_000_000,
        "a sample is logged when received"
    );
    let deviation = states[0].message.deviation_m.unwrap();
    assert!((deviation - 0.5).abs() < 1e-9, "{deviation}");
    let faults = recording.messages::<FaultRecord>().unwrap();
    assert_eq!(faults[1].message.status, FaultStatus::Confirmed);
    let segments = recording.messages::<PlannedSegment>().unwrap();
    assert_eq!(
        segments[0].message,
        PlannedSegment::new(0, 1, 0, &segment())
    );
    let oracle = recording.messages::<OracleRecord>().unwrap();
    assert_eq!(oracle[0].message, oracle_record());
    let safety = recording.messages::<SafetyRecord>().unwrap();
    assert_eq!(safety[0].message.message, "RTK fix lost");
}

#[tokio::test(start_paused = true)]
async fn sim_records_carry_the_hidden_truth_at_their_simulation_time() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    record_every_channel(&path, &scenario()).await;
    let recording = Recording::read(&path).unwrap();
    let truth = recording.messages::<TruthRecord>().unwrap();
    assert_eq!(truth[0].log_time_ns, 1_030_000_000);
    assert!(
        truth[0].message.uwb.x.is_nan(),
        "a NaN estimate reads back as NaN"
    );
    assert_eq!(truth[0].message.uwb_error_m, None);
    let ranges = recording.messages::<SimRange>().unwrap();
    assert_eq!(ranges.len(), 2);
    assert_eq!(
        ranges[0].log_time_ns, 930_000_000,
        "sim 900 ms is 100 ms before the truth"
    );
    let SimRange::Request {
        path,
        outcome,
        range_m,
        ..
    } = &ranges[0].message
    else {
        panic!("expected a request, got {:?}", ranges[0].message);
    };
    assert_eq!(path.map(|p| p.kind), Some(RadioPathKind::Reflected));
    assert_eq!(*outcome, RangeOutcome::Measured);
    assert_eq!(*range_m, Some(12.25));
    let faults = recording.messages::<SimFault>().unwrap();
    assert_eq!(
        (faults[0].message.before, faults[0].message.after),
        (12.25, 13.75)
    );
    let events = recording.messages::<SimEvent>().unwrap();
    assert_eq!(events[0].message.event, SimEventKind::WatchdogExpired);
}

#[test]
fn every_kind_of_simulated_range_reads_back_from_protobuf_as_written() {
    let path = |kind, wall: Option<usize>| RadioPathRecord {
        kind,
        length_m: (kind != RadioPathKind::Blocked).then_some(12.5),
        wall,
        direct_m: wall.map(|_| 9.0),
    };
    let ranges = [
        SimRange::Request {
            sim_ms: 900,
            anchor: 50,
            path: Some(path(RadioPathKind::Reflected, Some(3))),
            true_range_m: Some(9.1),
            outcome: RangeOutcome::Measured,
            range_m: Some(f64::from(12.25_f32)),
        },
        SimRange::Request {
            sim_ms: 1000,
            anchor: 234,
            path: Some(path(RadioPathKind::Blocked, None)),
            true_range_m: Some(4.0),
            outcome: RangeOutcome::Blocked,
            range_m: None,
        },
        SimRange::Request {
            sim_ms: 1100,
            anchor: 7,
            path: None,
            true_range_m: None,
            outcome: RangeOutcome::NoResponder,
            range_m: None,
        },
        SimRange::Request {
            sim_ms: 1200,
            anchor: 50,
            path: Some(path(RadioPathKind::LineOfSight, None)),
            true_range_m: Some(3.0),
            outcome: RangeOutcome::Dropped,
            range_m: None,
        },
        SimRange::Fused {
            sim_ms: 1300,
            anchor: 50,
            range_m: f64::from(13.75_f32),
            moved: true,
        },
    ];
    for range in &ranges {
        let bytes = range.encode().unwrap();
        let back = SimRange::from_protobuf(&bytes).unwrap().unwrap();
        assert_eq!(&back, range);
        let json = serde_json::to_vec(range).unwrap().len();
        assert!(
            bytes.len() * 3 < json,
            "{} bytes against {json} in JSON: {range:?}",
            bytes.len()
        );
    }
    // A fused range that was not finite is left out and reads back as NaN.
    let lost = SimRange::Fused {
        sim_ms: 1,
        anchor: 1,
        range_m: f64::INFINITY,
        moved: false,
    };
    let back = SimRange::from_protobuf(&lost.encode().unwrap())
        .unwrap()
        .unwrap();
    assert!(matches!(back, SimRange::Fused { range_m, .. } if range_m.is_nan()));
    // A number that stands for no outcome is an error naming the field, not a guess.
    let mut bytes = ranges[0].encode().unwrap();
    bytes.extend([9 << 3, 7]); // outcome = 7
    let error = SimRange::from_protobuf(&bytes).unwrap().unwrap_err();
    assert_eq!(error.to_string(), "field outcome: 7 stands for no value");
}

#[tokio::test(start_paused = true)]
async fn the_scenario_and_campaign_are_metadata_records() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let s = scenario();
    record_every_channel(&path, &s).await;
    let recording = Recording::read(&path).unwrap();
    assert_eq!(recording.check_format().map_err(|e| e.to_string()), Ok(()));
    let header = recording.metadata("drivecheck.recording").unwrap();
    assert_eq!(header["format"], RECORDING_FORMAT);
    assert_eq!(header["schema_version"], RECORDING_VERSION.to_string());
    let scenario = recording.metadata("drivecheck.scenario").unwrap();
    assert_eq!(scenario["hash"], s.hash());
    let reloaded = scenarios::from_toml_str(&scenario["toml"], "recording").unwrap();
    assert_eq!(reloaded.scenario.hash(), s.hash());
    let campaign = recording.metadata("drivecheck.campaign").unwrap();
    assert_eq!(campaign["seed"], "42");
    let record = CampaignRecord::from_json(&campaign["json"]).unwrap();
    assert_eq!(record.scenario.hash, Some(s.hash()));
}

#[tokio::test(start_paused = true)]
async fn every_channel_has_a_schema_its_messages_follow() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    record_every_channel(&path, &scenario()).await;
    let recording = Recording::read(&path).unwrap();
    for topic in Topic::ALL {
        let channel = recording.channel(topic).unwrap();
        assert_eq!(channel.message_encoding, topic.encoding().name());
        if topic.encoding() == Encoding::Protobuf {
            protobuf_messages_follow_their_schema(&recording, topic);
            continue;
        }
        assert_eq!(channel.schema_encoding, "jsonschema");
        assert_eq!(channel.schema_name, topic.schema_name());
        let schema: Value = serde_json::from_slice(&channel.schema).unwrap();
        assert_eq!(schema["type"], "object", "{topic}");
        assert_eq!(schema["title"], topic.schema_name());
        assert!(
            !channel.schema.windows(4).any(|w| w == b"$ref"),
            "{topic}: the schema is not self-contained"
        );
        if let Err(e) = foxglove_reads(&schema, topic.name()) {
            panic!("Foxglove refuses the schema of {topic}: {e}");
        }
        assert!(
            !raw_messages(&recording, topic).is_empty(),
            "{topic}: no messages to check"
        );
    }
    messages_follow_their_schemas_to_the_reference_validator(&path);
}

/// Every JSON message of the recording at `path` follows its channel's schema, and every schema
/// is a valid draft 2020-12 schema (checked against the meta-schema), to the reference validator
/// ([`reference_validator`]).
fn messages_follow_their_schemas_to_the_reference_validator(path: &Path) {
    let script = r#"
import sys, json
from jsonschema import Draft202012Validator
from mcap.reader import make_reader
validators, counts = {}, {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        if channel.message_encoding != "json":
            continue
        if channel.topic not in validators:
            document = json.loads(schema.data)
            Draft202012Validator.check_schema(document)
            validators[channel.topic] = Draft202012Validator(document)
        errors = sorted(validators[channel.topic].iter_errors(json.loads(message.data)), key=str)
        if errors:
            print(f"{channel.topic} message {counts.get(channel.topic, 0)} does not follow its schema: {errors[0].message} at {list(errors[0].absolute_path)}\n{message.data.decode()}")
            sys.exit(3)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
print(json.dumps(counts))
"#;
    let Some(counts) = reference_validator(script, &[path.as_os_str()]) else {
        return;
    };
    for topic in Topic::ALL {
        if topic.encoding() != Encoding::Protobuf {
            assert!(
                counts[topic.name()].as_u64().unwrap_or(0) > 0,
                "{topic}: no message checked: {counts}"
            );
        }
    }
}

/// A protobuf channel's schema is a `FileDescriptorSet` declaring the schema name, and each of
/// its messages decodes by it as Foxglove decodes it (`prost-reflect`, a reader of its own),
/// every field known to the schema.
fn protobuf_messages_follow_their_schema(recording: &Recording, topic: Topic) {
    let channel = recording.channel(topic).unwrap();
    assert_eq!(channel.schema_encoding, "protobuf", "{topic}");
    assert_eq!(channel.schema_name, topic.schema_name());
    let pool = prost_reflect::DescriptorPool::decode(channel.schema.as_slice())
        .unwrap_or_else(|e| panic!("{topic}: not a FileDescriptorSet: {e}"));
    let descriptor = pool
        .get_message_by_name(topic.schema_name())
        .unwrap_or_else(|| {
            panic!(
                "{topic}: the schema does not declare {}",
                topic.schema_name()
            )
        });
    let messages: Vec<&[u8]> = recording.payloads(topic).collect();
    assert!(!messages.is_empty(), "{topic}: no messages to check");
    for (i, data) in messages.into_iter().enumerate() {
        let message = prost_reflect::DynamicMessage::decode(descriptor.clone(), data)
            .unwrap_or_else(|e| panic!("{topic} message {i} does not decode by its schema: {e}"));
        assert_eq!(
            message.unknown_fields().count(),
            0,
            "{topic} message {i} has fields its schema does not declare"
        );
    }
}

/// Whether each of `instances` follows `schema` (itself checked against the meta-schema), to
/// the reference validator; `None` where it is not installed (said by [`reference_validator`]).
fn follows(schema: &Value, instances: &[Value]) -> Option<Vec<bool>> {
    let script = r#"
import sys, json
from jsonschema import Draft202012Validator
schema, instances = json.loads(sys.argv[1]), json.loads(sys.argv[2])
Draft202012Validator.check_schema(schema)
validator = Draft202012Validator(schema)
print(json.dumps([validator.is_valid(i) for i in instances]))
"#;
    let (schema, instances) = (
        schema.to_string(),
        Value::from(instances.to_vec()).to_string(),
    );
    let verdicts = reference_validator(script, &[schema.as_ref(), instances.as_ref()])?;
    Some(serde_json::from_value(verdicts).unwrap())
}

/// Runs `script` with `args` in the reference JSON-schema validator's Python — the `jsonschema`
/// package, in the Python `DRIVECHECK_PYTHON` names (`.ci/run` installs it into a virtual
/// environment; no Rust validator is built for the tests) — and returns the JSON it printed.
/// Where the package (or Python) is missing, says so on standard error and returns `None`: a
/// failure instead when `DRIVECHECK_REQUIRE` names `python-jsonschema`.
fn reference_validator(script: &str, args: &[&std::ffi::OsStr]) -> Option<Value> {
    let python = std::env::var("DRIVECHECK_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .args(args)
        .output();
    let why = match out {
        Err(e) => format!("{python} does not run: {e}"),
        Ok(out) if out.status.success() => {
            return Some(serde_json::from_slice(&out.stdout).unwrap());
        }
        Ok(out) if String::from_utf8_lossy(&out.stderr).contains("No module named") => format!(
            "the jsonschema or mcap package is not installed ({python}): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ),
        Ok(out) => panic!(
            "the reference validator refused:\n{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
    };
    let required = std::env::var("DRIVECHECK_REQUIRE").unwrap_or_default();
    assert!(
        !required.split(',').any(|r| r.trim() == "python-jsonschema"),
        "python-jsonschema is required (DRIVECHECK_REQUIRE={required}) but {why}"
    );
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "skipped (python-jsonschema): {why}");
    None
}

/// Whether Foxglove's JSON-schema reader takes `schema`, by the rules of the reader in
/// Lichtblick, Foxglove Studio's open fork (`packages/mcap-support/src/parseJsonSchema.ts`,
/// which throws, and so drops the channel, on anything else): an object whose every property
/// has one known type, an array's items too, and a `oneOf` only of numeric constants.
fn foxglove_reads(schema: &Value, path: &str) -> Result<(), String> {
    if schema["type"] != "object" {
        return Err(format!(
            "{path}: expected \"type\": \"object\", got {}",
            schema["type"]
        ));
    }
    let properties = schema.get("properties").and_then(Value::as_object);
    for (name, field) in properties.into_iter().flatten() {
        let path = format!("{path}.{name}");
        if let Some(alternatives) = field.get("oneOf").and_then(Value::as_array) {
            if alternatives.iter().all(|a| a["const"].is_number()) {
                continue;
            }
            return Err(format!(
                "{path}: oneOf alternatives must have number values"
            ));
        }
        match field["type"].as_str() {
            Some("boolean" | "number" | "integer") => {}
            Some("string") => match field.get("contentEncoding") {
                None => {}
                Some(encoding) if encoding == "base64" => {}
                Some(_) => return Err(format!("{path}: unsupported contentEncoding")),
            },
            Some("object") => foxglove_reads(field, &path)?,
            Some("array") => match field["items"]["type"].as_str() {
                Some("boolean" | "number" | "integer") => {}
                Some("string") if field["items"].get("contentEncoding").is_none() => {}
                Some("object") => foxglove_reads(&field["items"], &path)?,
                _ => return Err(format!("{path}: unsupported array item {}", field["items"])),
            },
            _ => return Err(format!("{path}: unsupported type {}", field["type"])),
        }
    }
    Ok(())
}

#[test]
fn the_foxglove_rules_refuse_what_its_reader_throws_on() {
    let nullable = serde_json::json!({"type": "object", "properties": {
        "x": {"type": ["number", "null"]}}});
    assert!(foxglove_reads(&nullable, "").is_err());
    let union = serde_json::json!({"type": "object", "properties": {
        "kind": {"oneOf": [{"const": "a"}, {"const": "b"}]}}});
    assert!(foxglove_reads(&union, "").is_err());
    let untyped_items = serde_json::json!({"type": "object", "properties": {
        "arrows": {"type": "array", "items": true}}});
    assert!(foxglove_reads(&untyped_items, "").is_err());
    let numbered = serde_json::json!({"type": "object", "properties": {
        "type": {"oneOf": [{"const": 0}, {"const": 1}]},
        "points": {"type": "array", "items": {"type": "object", "properties": {
            "x": {"type": "number"}}}}}});
    assert_eq!(foxglove_reads(&numbered, ""), Ok(()));
}

/// `topic`'s messages as JSON values, as written.
fn raw_messages(recording: &Recording, topic: Topic) -> Vec<Value> {
    recording
        .payloads(topic)
        .map(|bytes| serde_json::from_slice(bytes).unwrap())
        .collect()
}

#[test]
fn a_derived_schema_refuses_what_its_record_type_would_not_read() {
    let good = serde_json::json!({"sim_ms": 5, "event": "watchdog_expired"});
    let extra = serde_json::json!({"sim_ms": 5, "event": "watchdog_expired", "x": 1});
    let wrong = serde_json::json!({"sim_ms": 5, "event": "reboot"});
    let negative = serde_json::json!({"sim_ms": -5, "event": "watchdog_expired"});
    if let Some(verdicts) = follows(
        &schema::schema(Topic::SimEvents),
        &[good, extra, wrong, negative],
    ) {
        assert_eq!(verdicts, [true, false, false, false]);
    }
}

#[test]
fn a_number_that_was_not_finite_is_left_out_and_read_back_as_nan() {
    let topic = Topic::CarState;
    let mut nan = sample(Instant::now(), 1.0);
    nan.state.speed = f64::NAN;
    let state = CarStateRecord::new(&nan, Instant::now());
    let written = serde_json::to_value(&state).unwrap();
    assert!(written.get("speed_mps").is_none(), "{written}");
    let back: CarStateRecord = serde_json::from_value(written.clone()).unwrap();
    assert!(back.speed_mps.is_nan());
    // Version 1 wrote it as null: still read, as NaN — and not what the schema says now.
    let mut version1 = written.clone();
    version1["speed_mps"] = Value::Null;
    let back: CarStateRecord = serde_json::from_value(version1.clone()).unwrap();
    assert!(back.speed_mps.is_nan());
    if let Some(verdicts) = follows(&schema::schema(topic), &[written, version1]) {
        assert_eq!(verdicts, [true, false]);
    }
}

/// Version 3 keeps the RTK and UWB positions on the pose channels only; a position that is not
/// finite (no pose) stays in the state. Every state reads back as it was, with its deviation.
#[tokio::test(start_paused = true)]
async fn states_join_their_poses_and_keep_what_has_no_pose() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let s = scenario();
    let origin = Instant::now();
    let mut recorder = create(&path, &s, false, origin);
    let mut samples = Vec::new();
    for i in 0..6 {
        let mut sample = sample(Instant::now(), 1.0 + f64::from(i) * 0.123_4);
        match i {
            1 => sample.state.px_uwb = f64::NAN,
            2 => sample.state.py = f64::INFINITY,
            3 => {
                sample.state.px = f64::NAN;
                sample.state.py_uwb = f64::NAN;
            }
            4 => sample.state.yaw = f64::NAN,
            _ => {}
        }
        recorder.car_state(&sample).unwrap();
        samples.push(sample);
        advance(Duration::from_millis(50)).await;
    }
    recorder.finish().unwrap();
    let recording = Recording::read(&path).unwrap();
    assert_eq!(
        recording.encoding(Topic::CarState),
        Some(Encoding::Protobuf)
    );
    // Poses only for the finite positions: 6 − 2 RTK, 6 − 2 UWB.
    assert_eq!(recording.count(Topic::FoxgloveRtk), 4);
    assert_eq!(recording.count(Topic::FoxgloveUwb), 4);
    let read = recording.messages::<CarStateRecord>().unwrap();
    assert_eq!(read.len(), samples.len());
    for (read, sample) in read.iter().zip(&samples) {
        let written = CarStateRecord::new(sample, origin);
        // NaN ≠ NaN: compare the bits.
        let bits = |r: &CarStateRecord| {
            [
                r.rtk.x,
                r.rtk.y,
                r.rtk.yaw_deg,
                r.uwb.x,
                r.uwb.y,
                r.speed_mps,
            ]
            .map(f64::to_bits)
        };
        assert_eq!(bits(&read.message), bits(&written));
        assert_eq!(read.message.deviation_m, written.deviation_m);
        assert_eq!(read.message.received_at_ns, written.received_at_ns);
    }
}

/// The RTK pose heads where the car heads: the firmware's yaw is clockwise from east (90° is
/// south), a pose's rotation counter-clockwise.
#[test]
fn the_rtk_pose_heads_where_the_car_heads() {
    let origin = Instant::now();
    let mut south = sample(origin, 1.0);
    south.state.yaw = 90.0;
    let state = CarStateRecord::new(&south, origin);
    let (rtk, _) = foxglove::poses(&state, foxglove::Time::from_ns(0));
    let q = rtk.unwrap().0.pose.orientation;
    let heading = 2.0 * q.z.atan2(q.w);
    assert!(
        (heading + std::f64::consts::FRAC_PI_2).abs() < 1e-12,
        "heading {heading} rad"
    );
}

#[test]
fn a_probe_is_one_of_the_ids_the_firmware_knows() {
    let topic = Topic::Faults;
    let fault = Fault {
        probe: Probe::UwbRange(234),
        kind: FaultKind::Offset,
        param: 1.0,
        start: 0,
        duration: 5,
        at: None,
    };
    let written = serde_json::to_value(FaultRecord::sent(0, 1, &fault)).unwrap();
    assert_eq!(written["fault"]["probe"], "uwb_range_234");
    let mut unknown = written.clone();
    unknown["fault"]["probe"] = "uwb_range_x".into();
    if let Some(verdicts) = follows(&schema::schema(topic), &[written, unknown]) {
        assert_eq!(verdicts, [true, false]);
    }
}

#[tokio::test(start_paused = true)]
async fn a_killed_recorder_leaves_every_chunk_written_before_the_kill() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let s = scenario();
    let origin = Instant::now();
    let mut recorder = create(&path, &s, false, origin);
    recorder.car_state(&sample(origin, 1.0)).unwrap();
    advance(Duration::from_millis(500)).await;
    recorder.car_state(&sample(Instant::now(), 2.0)).unwrap();
    advance(Duration::from_millis(600)).await;
    // 1.1 s after the chunk opened: this message closes it and opens the next one.
    recorder.car_state(&sample(Instant::now(), 3.0)).unwrap();
    recorder.write(&test_started(1)).unwrap();
    // A kill: no destructor runs, the open chunk and the file buffer are lost.
    std::mem::forget(recorder);

    let recording = Recording::read(&path).unwrap();
    assert!(recording.check_format().is_ok());
    assert!(!recording.is_complete());
    assert!(recording.cut_short().is_some());
    let states = recording.messages::<CarStateRecord>().unwrap();
    let xs: Vec<f64> = states.iter().map(|m| m.message.rtk.x).collect();
    assert_eq!(xs, [1.0, 2.0]);
    assert_eq!(recording.count(Topic::Tests), 0);
    assert!(recording.metadata("drivecheck.scenario").is_some());
    assert!(recording.channel(Topic::SafetyEvents).is_some());
    assert!(
        recording.channel(Topic::SimTruth).is_none(),
        "a real car has no /sim channels"
    );
}

fn test_started(test_index: usize) -> TestEvent {
    TestEvent {
        test_index,
        event: TestEventKind::Started { commands: 4 },
    }
}

#[tokio::test(start_paused = true)]
async fn a_recorder_dropped_without_finish_completes_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let mut recorder = create(&path, &scenario(), false, Instant::now());
    recorder.write(&test_started(0)).unwrap();
    drop(recorder);
    let recording = Recording::read(&path).unwrap();
    assert!(recording.is_complete(), "{:?}", recording.cut_short());
    assert_eq!(recording.count(Topic::Tests), 1);
}

#[tokio::test(start_paused = true)]
async fn a_truncated_recording_reads_every_whole_chunk_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    let mut recorder = create(&path, &scenario(), false, Instant::now());
    for test_index in 0..12 {
        recorder.write(&test_started(test_index)).unwrap();
        if test_index % 3 == 2 {
            recorder.flush().unwrap();
        }
    }
    recorder.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // The first chunk holds the area on `/foxglove/area`, written when the file is created.
    let chunk_ends = chunk_ends(&bytes)[1..].to_vec();
    assert_eq!(chunk_ends.len(), 4);
    let mut lengths: Vec<usize> = (0..bytes.len()).step_by(11).collect();
    lengths.extend(chunk_ends.iter().flat_map(|&end| [end - 1, end, end + 1]));
    for length in lengths {
        let Ok(recording) = Recording::from_bytes(&bytes[..length]) else {
            assert!(length < 100, "a {length}-byte prefix was refused");
            continue;
        };
        // Whole messages of a chunk cut in the middle are read too, never a partial one.
        let whole_chunks = chunk_ends.iter().filter(|&&end| end <= length).count();
        let tests = recording.messages::<TestEvent>().unwrap();
        let indices: Vec<usize> = tests.iter().map(|m| m.message.test_index).collect();
        let expected: Vec<usize> = (0..indices.len()).collect();
        assert_eq!(indices, expected, "prefix of {length} bytes");
        let at_a_boundary = chunk_ends.contains(&length);
        let most = if at_a_boundary { 0 } else { 2 };
        let read = indices.len();
        assert!(
            (whole_chunks * 3..=whole_chunks * 3 + most).contains(&read),
            "prefix of {length} bytes: {read} messages, {whole_chunks} whole chunks"
        );
    }
}

/// The offset just past each chunk record holding messages (the first chunk holds the schemas
/// and channels).
fn chunk_ends(bytes: &[u8]) -> Vec<usize> {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    summary
        .chunk_indexes
        .iter()
        .filter(|c| !c.message_index_offsets.is_empty())
        .map(|c| usize::try_from(c.chunk_start_offset + c.chunk_length).unwrap())
        .collect()
}

#[test]
fn bytes_that_are_not_mcap_are_refused() {
    let error = Recording::from_bytes(b"{\"format\": \"drivecheck-case\"}").unwrap_err();
    assert!(matches!(error, RecordingError::NotMcap(_)), "{error}");
}

#[test]
fn another_mcap_file_is_not_a_drivecheck_recording() {
    let mut bytes = Vec::new();
    let mut writer = mcap::Writer::new(std::io::Cursor::new(&mut bytes)).unwrap();
    writer.finish().unwrap();
    drop(writer);
    let recording = Recording::from_bytes(&bytes).unwrap();
    assert!(recording.is_complete());
    let error = recording.check_format().unwrap_err();
    assert!(
        matches!(
            error,
            RecordingError::UnsupportedFormat { format: None, .. }
        ),
        "{error}"
    );
}

/// An MCAP file with the `drivecheck.recording` header of `version` and one `/car/state` message,
/// `state` as written.
fn recording_of_version(version: &str, state: &Value) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut writer = mcap::Writer::new(std::io::Cursor::new(&mut bytes)).unwrap();
    let header = [("format", RECORDING_FORMAT), ("schema_version", version)]
        .map(|(k, v)| (k.to_owned(), v.to_owned()));
    let metadata = mcap::records::Metadata {
        name: "drivecheck.recording".to_owned(),
        metadata: header.into_iter().collect(),
    };
    writer.write_metadata(&metadata).unwrap();
    let topic = Topic::CarState;
    let schema = writer
        .add_schema(topic.schema_name(), "jsonschema", b"{}")
        .unwrap();
    let channel = writer
        .add_channel(schema, topic.name(), "json", &Default::default())
        .unwrap();
    let header = mcap::records::MessageHeader {
        channel_id: channel,
        sequence: 1,
        log_time: 12_000_000,
        publish_time: 12_000_000,
    };
    let payload = serde_json::to_vec(state).unwrap();
    writer.write_to_known_channel(&header, &payload).unwrap();
    writer.finish().unwrap();
    drop(writer);
    bytes
}

#[test]
fn a_version_1_recording_is_read_with_its_nulls_as_nan() {
    let mut nan = sample(Instant::now(), 1.0);
    nan.state.speed = f64::NAN;
    nan.state.px_uwb = f64::NAN;
    let mut state = serde_json::to_value(CarStateRecord::new(&nan, Instant::now())).unwrap();
    // What version 1 wrote for them.
    state["speed_mps"] = Value::Null;
    state["uwb"]["x"] = Value::Null;
    state["deviation_m"] = Value::Null;
    let recording = Recording::from_bytes(&recording_of_version("1", &state)).unwrap();
    recording.check_format().unwrap();
    let read = recording.messages::<CarStateRecord>().unwrap();
    assert_eq!(read.len(), 1);
    let read = &read[0].message;
    assert!(read.speed_mps.is_nan() && read.uwb.x.is_nan());
    assert_eq!(read.deviation_m, None);
    let future = Recording::from_bytes(&recording_of_version("5", &state)).unwrap();
    let error = future.check_format().unwrap_err();
    assert!(
        matches!(error, RecordingError::UnsupportedFormat { .. }),
        "{error}"
    );
}

#[test]
fn topics_have_unique_names_and_round_trip() {
    for topic in Topic::ALL {
        assert_eq!(Topic::from_name(topic.name()), Some(topic));
    }
    let mut names: Vec<&str> = Topic::ALL.iter().map(|t| t.name()).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), Topic::ALL.len());
}

#[test]
fn a_recorder_can_move_into_a_task() {
    fn send<T: Send + 'static>() {}
    send::<Recorder>();
    send::<Recording>();
}
