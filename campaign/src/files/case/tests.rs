use super::*;
use crate::files::{
    CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION, CampaignRecord, CampaignSummary, CaseError,
};
use crate::model::{Campaign, plan_test, start_tail};
use crate::oracle::FailurePolicy;
use crate::oracle::{SegmentOracle, SegmentVerdict};
use crate::safety::SafetyConfig;
use crate::streaming::StreamingConfig;

pub(crate) fn scenario(name: &str) -> Scenario {
    scenarios::bundled::load(name).unwrap().scenario
}

/// A hand-made case whose segment *i* was driven with a largest deviation of `maxima[i]`,
/// judged against 1 m.
pub(crate) fn case_with_segments(maxima: &[f64]) -> Case {
    let mut case: Case = parse(
        r#"{"format": "drivecheck-case", "schema_version": 3,
            "scenario": {"name": "x"}, "commands": []}"#,
    )
    .unwrap();
    for (segment_index, &max) in maxima.iter().enumerate() {
        let mut oracle = SegmentOracle::new();
        oracle.push(Point::new(max, 0.0), Point::new(0.0, 0.0));
        case.segments.push(SegmentResult {
            segment_index,
            command_index: segment_index,
            faults_preceding: vec![],
            faults_active: vec![],
            oracle: oracle.result(1.0),
        });
    }
    case
}

fn run_case() -> (Scenario, Case) {
    let s = scenario("parking-lot-2anchors");
    let campaign = Campaign {
        seed: 99,
        tests: 10,
        no_faults: false,
    };
    let plan = plan_test(&s, &campaign, 9, start_tail(&s).unwrap()).unwrap();
    let settings = Settings::new(&s, 10, FailurePolicy::default())
        .with_runtime(SafetyConfig::default(), StreamingConfig::default());
    let mut case = Case::planned(&plan, &s, 99, false, settings);
    let mut oracle = SegmentOracle::new();
    oracle.push(Point::new(0.4, 0.3), Point::new(0.0, 0.0));
    oracle.push(Point::new(1.2, 0.0), Point::new(0.1, 0.0));
    let (command_index, _) = plan.segments().nth(1).unwrap();
    case.segments.push(SegmentResult {
        segment_index: 1,
        command_index,
        faults_preceding: plan.faults_before(command_index),
        faults_active: vec![],
        oracle: oracle.result(1.0),
    });
    case.return_route = vec![RoutePointRecord {
        x: -26.0,
        y: -60.0,
        speed: 0.8,
    }];
    case.return_clearance_m = Some(0.25);
    case.verdict = Some(Verdict::Failed);
    case.reason = Some("segment 1: deviation 1.10 m above 1.00 m".to_owned());
    case.abort = Some(Abort::new(
        crate::safety::AbortReason::Interrupted,
        std::time::Duration::from_millis(9000),
    ));
    case.streaming = Some(StreamingRecord {
        appends: vec![AppendRecord {
            decided_at: 1500,
            time_to_end: 2100,
            lead: 1800,
            confirmed_after: Some(160),
        }],
        starvations_ms: vec![],
        smallest_margin_s: Some(1.94),
    });
    (s, case)
}

#[test]
fn a_case_survives_a_round_trip_through_json() {
    let (s, case) = run_case();
    assert_eq!(case.segments[0].oracle.verdict, SegmentVerdict::Failed);
    let json = case.to_json().unwrap();
    let back = Case::from_json(&json).unwrap();
    assert_eq!(back, case);
    assert_eq!(back.check().map_err(|e| e.to_string()), Ok(()));
    assert_eq!(back.check_route(&s).map_err(|e| e.to_string()), Ok(()));
}

#[test]
fn recorded_commands_give_back_the_planned_commands() {
    let s = scenario("parking-lot-2anchors");
    let campaign = Campaign {
        seed: 5,
        tests: 3,
        no_faults: false,
    };
    let plan = plan_test(&s, &campaign, 2, start_tail(&s).unwrap()).unwrap();
    for command in &plan.commands {
        let record = CommandRecord::from(command);
        assert_eq!(record.to_command(), *command);
    }
}

#[test]
fn a_campaign_record_survives_a_round_trip_through_json() {
    let s = scenario("parking-lot-2anchors");
    let record = CampaignRecord {
        header: Header::current(CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION),
        seed: 42,
        no_faults: true,
        scenario: ScenarioRef::of(&s),
        settings: Settings::new(&s, 10, FailurePolicy::ContinueAndRecord),
        car: "sim".to_owned(),
        car_profile: Some(crate::files::CarProfileRef {
            name: "car.toml".to_owned(),
            hash: "ab".repeat(32),
        }),
        car_firmware_version: Some("12.3".to_owned()),
        car_firmware_tree_hash: None,
        started_at: "2026-11-22T10:55:21Z".to_owned(),
        ended_at: Some("2026-11-22T10:56:02Z".to_owned()),
        summary: Some(CampaignSummary {
            tests: 10,
            passed: 8,
            failed: 1,
            aborted: 1,
            worst_deviation_m: Some(1.42),
            failing_cases: vec!["case-003.json".to_owned(), "case-007.json".to_owned()],
            uwb_not_tested: None,
            coverage: None,
        }),
        replay_of: None,
        cases_from: None,
        shard: None,
        sessions: Vec::new(),
        cars: Vec::new(),
    };
    let back = CampaignRecord::from_json(&record.to_json().unwrap()).unwrap();
    assert_eq!(back, record);
}

/// The JSON blocks of the documentation page, in order.
pub(crate) fn doc_examples() -> Vec<&'static str> {
    let doc = include_str!("../../../../docs/case-format.md");
    doc.split("```json\n")
        .skip(1)
        .filter_map(|block| block.split("\n```").next())
        .collect()
}

#[test]
fn the_documented_hand_written_case_is_valid_and_drivable() {
    let examples = doc_examples();
    let case = Case::from_json(examples[0]).unwrap();
    assert_eq!(case.check().map_err(|e| e.to_string()), Ok(()));
    let s = scenario(&case.scenario.name);
    assert_eq!(case.check_route(&s).map_err(|e| e.to_string()), Ok(()));
    assert!(case.verdict.is_none());
}

#[test]
fn the_documented_recorded_case_and_campaign_parse() {
    let examples = doc_examples();
    let case = Case::from_json(examples[1]).unwrap();
    assert_eq!(case.check().map_err(|e| e.to_string()), Ok(()));
    assert_eq!(case.verdict, Some(Verdict::Failed));
    CampaignRecord::from_json(examples[2]).unwrap();
}

#[test]
fn another_format_or_a_newer_version_is_refused() {
    let (_, case) = run_case();
    let mut other = case.clone();
    other.header.format = CAMPAIGN_FORMAT.to_owned();
    let error = Case::from_json(&other.to_json().unwrap()).unwrap_err();
    assert!(matches!(error, CaseError::WrongFormat { .. }));
    let mut newer = case;
    newer.header.schema_version = CASE_SCHEMA_VERSION + 1;
    let error = Case::from_json(&newer.to_json().unwrap()).unwrap_err();
    assert!(
        matches!(error, CaseError::UnsupportedVersion { found, .. } if found == CASE_SCHEMA_VERSION + 1),
        "{error}"
    );
    assert!(
        error
            .to_string()
            .ends_with("(this drivecheck reads 1, 2 and 3)"),
        "{error}"
    );
}

#[test]
fn a_parse_error_names_the_field() {
    let text = r#"{"format": "drivecheck-case", "schema_version": 1,
        "scenario": {"name": "x"},
        "commands": [{"command": "run_segments", "points": [{"x": 1, "y": 2, "speed": "fast"}]}]}"#;
    let error = Case::from_json(text).unwrap_err().to_string();
    assert!(error.starts_with("commands[0]: invalid type"), "{error}");
    let text = r#"{"format": "drivecheck-case", "schema_version": 1, "scenario": {"name": "x"},
        "commands": [{"command": "add_fault", "probe": "uwb_range_x", "kind": "offset",
        "param": 1.0, "start": 0, "duration": 1}]}"#;
    let error = Case::from_json(text).unwrap_err().to_string();
    assert!(error.contains("unknown probe"), "{error}");
}

#[test]
fn check_refuses_unusable_values() {
    let base = |command: CommandRecord| Case {
        header: Header::untooled(CASE_FORMAT, 1),
        campaign_seed: None,
        test_index: None,
        scenario: ScenarioRef {
            name: "x".to_owned(),
            hash: None,
        },
        settings: None,
        car_profile: None,
        car: None,
        no_faults: false,
        commands: vec![command],
        return_route: vec![],
        return_clearance_m: None,
        segments: vec![],
        verdict: None,
        reason: None,
        abort: None,
        streaming: None,
        fault_places: Vec::new(),
        timing: None,
        explanation: Vec::new(),
    };
    let point = |speed| RoutePointRecord {
        x: 0.0,
        y: 0.0,
        speed,
    };
    let stopped = base(CommandRecord::RunSegments {
        intent: None,
        points: vec![point(0.0)],
        margin: vec![],
    });
    assert!(
        stopped
            .check()
            .unwrap_err()
            .to_string()
            .starts_with("commands[0].points[0].speed")
    );
    let empty = base(CommandRecord::RunSegments {
        intent: None,
        points: vec![],
        margin: vec![],
    });
    assert!(empty.check().is_err());
    let miscounted = base(CommandRecord::RunSegments {
        intent: Some(IntentRecord {
            seed: 1,
            points: 2,
            speed_mps: 1.0,
        }),
        points: vec![point(1.0)],
        margin: vec![],
    });
    assert!(miscounted.check().is_err());
    let permanent = base(CommandRecord::AddFault {
        probe: Probe::UwbYaw,
        kind: FaultKind::Offset,
        param: 3.0,
        start: 0,
        duration: 0,
        at: None,
    });
    assert!(permanent.check().is_err());
    let mut dangling = base(CommandRecord::AddFault {
        probe: Probe::UwbYaw,
        kind: FaultKind::Offset,
        param: 3.0,
        start: 0,
        duration: 2,
        at: None,
    });
    dangling.segments.push(SegmentResult {
        segment_index: 0,
        command_index: 0,
        faults_preceding: vec![],
        faults_active: vec![],
        oracle: SegmentOracle::new().result(1.0),
    });
    assert!(dangling.check().is_err());
    let mut negative = base(CommandRecord::RunSegments {
        intent: None,
        points: vec![point(1.0)],
        margin: vec![],
    });
    assert_eq!(negative.check().map_err(|e| e.to_string()), Ok(()));
    negative.return_clearance_m = Some(-0.25);
    assert!(
        negative
            .check()
            .unwrap_err()
            .to_string()
            .starts_with("return_clearance_m")
    );
}

#[test]
fn check_refuses_speeds_and_fault_values_beyond_the_firmwares_ranges() {
    let case = |commands: &str| -> Case {
        parse(&format!(
            r#"{{"format": "drivecheck-case", "schema_version": 3,
                "scenario": {{"name": "x"}}, "commands": [{commands}]}}"#
        ))
        .unwrap()
    };
    let error = |commands: &str| case(commands).check().unwrap_err().to_string();
    let segment = |speed: &str| {
        format!(
            r#"{{"command": "run_segments", "points": [{{"x": 1, "y": 2, "speed": {speed}}}]}}"#
        )
    };
    let fault = |probe: &str, kind: &str, param: &str| {
        format!(
            r#"{{"command": "add_fault", "probe": "{probe}", "kind": "{kind}", "param": {param},
                "start": 0, "duration": 5}}"#
        )
    };
    assert_eq!(
        error(&segment("1e30")),
        "commands[0].points[0].speed: 1e30 m/s is beyond the firmware autopilot's top speed of \
         8.333 m/s (30 km/h)"
    );
    case(&segment("8.3")).check().unwrap();
    assert_eq!(
        error(&fault("uwb_yaw", "offset", "1e308")),
        "commands[0].param: 1e308 is outside -180..=180 (offset on uwb_yaw)"
    );
    assert_eq!(
        error(&fault("uwb_yaw", "set_to", "-181")),
        "commands[0].param: -181 is outside -180..=180 (set_to on uwb_yaw)"
    );
    assert!(
        error(&fault("uwb_range_50", "amplification", "1e30"))
            .starts_with("commands[0].param: 1e30 is beyond drivecheck's limit: at most 1000"),
    );
    assert!(
        error(&fault("uwb_travel_dist", "offset", "-5000"))
            .starts_with("commands[0].param: 5000 is beyond drivecheck's limit: at most 1000"),
    );
    assert_eq!(
        error(&fault("uwb_range_50", "bitflip", "32")),
        "commands[0].param: 32 is outside 0..=31 (bitflip on uwb_range_50)"
    );
    assert_eq!(
        error(&fault("uwb_range_50", "bitflip", "3.5")),
        "commands[0].param: must be a whole number, found 3.5 (bitflip on uwb_range_50)"
    );
    for (probe, kind, param) in [
        ("uwb_yaw", "offset", "-180"),
        ("uwb_yaw", "amplification", "3"),
        ("uwb_range_50", "set_to", "999"),
        ("uwb_range_50", "bitflip", "31"),
        ("uwb_travel_dist", "none", "1e300"),
    ] {
        let commands = fault(probe, kind, param);
        assert_eq!(case(&commands).check().map_err(|e| e.to_string()), Ok(()));
    }
    let late = fault("uwb_yaw", "offset", "1").replace("\"start\": 0", "\"start\": 4000000000");
    assert_eq!(
        error(&late),
        "commands[0].start: 4000000000 probe iterations is beyond drivecheck's limit of 1000000"
    );
}

#[test]
fn a_segment_outside_the_area_is_not_drivable() {
    let (s, mut case) = run_case();
    case.commands.insert(
        0,
        CommandRecord::RunSegments {
            intent: None,
            points: vec![RoutePointRecord {
                x: 1000.0,
                y: 1000.0,
                speed: 1.0,
            }],
            margin: vec![],
        },
    );
    assert!(matches!(
        case.check_route(&s),
        Err(CaseError::NotDrivable { command: 0, .. })
    ));
}

#[test]
fn a_recorded_verdict_that_contradicts_the_segments_is_refused() {
    let (_, case) = run_case();
    assert!(case.check().is_ok(), "failed, with a failed segment");
    let mut passed = case.clone();
    passed.verdict = Some(Verdict::Passed);
    let error = passed.check().unwrap_err().to_string();
    assert!(
        error.starts_with("verdict: `passed`, but not every segment"),
        "{error}"
    );
    let mut failed = case.clone();
    failed.segments.clear();
    let error = failed.check().unwrap_err().to_string();
    assert!(
        error.starts_with("verdict: `failed`, but no segment"),
        "{error}"
    );
    // An aborted test may have any results; a hand-written case none.
    failed.verdict = Some(Verdict::Aborted);
    assert!(failed.check().is_ok());
    failed.verdict = None;
    assert!(failed.check().is_ok());
}

#[test]
fn every_segment_verdict_must_be_the_oracles_on_its_own_statistics() {
    let (_, case) = run_case();
    let failed = case
        .segments
        .iter()
        .position(|s| s.oracle.verdict == SegmentVerdict::Failed)
        .expect("run_case has a failed segment");
    // A failed segment and the test edited to a pass, the statistics left as they were.
    let mut edited = case.clone();
    edited.verdict = Some(Verdict::Passed);
    for segment in &mut edited.segments {
        segment.oracle.verdict = SegmentVerdict::Passed;
    }
    let error = edited.check().unwrap_err().to_string();
    assert!(
        error.starts_with(&format!(
            "segments[{failed}].oracle.verdict: `passed`, but its statistics (largest deviation"
        )),
        "{error}"
    );
    assert!(error.ends_with("say `failed`"), "{error}");
    // A threshold raised in the segment (and not in the case's settings) is refused too.
    let mut raised = case.clone();
    raised.segments[failed].oracle.threshold_m = 100.0;
    raised.segments[failed].oracle.verdict = SegmentVerdict::Passed;
    let error = raised.check().unwrap_err().to_string();
    assert!(
        error.starts_with(&format!("segments[{failed}].oracle.threshold_m: 100 m")),
        "{error}"
    );
}

#[test]
fn an_unknown_field_is_refused_beside_the_header() {
    let text = r#"{"format": "drivecheck-case", "schema_version": 2, "colour": "red",
        "scenario": {"name": "x"}, "commands": []}"#;
    let error = Case::from_json(text).unwrap_err().to_string();
    assert!(error.contains("unknown field `colour`"), "{error}");
    let text = r#"{"schema_version": 2, "scenario": {"name": "x"}, "commands": []}"#;
    let error = Case::from_json(text).unwrap_err().to_string();
    assert!(error.contains("missing field `format`"), "{error}");
}

#[test]
fn the_header_comes_first_and_a_missing_tool_version_is_left_out() {
    let (_, case) = run_case();
    let json = case.to_json().unwrap();
    let expected = format!(
        "{{\n  \"format\": \"drivecheck-case\",\n  \"schema_version\": {CASE_SCHEMA_VERSION},\n  \
         \"tool_version\": \"{}\",\n  \"campaign_seed\": 99,",
        crate::files::tool_version()
    );
    assert!(json.starts_with(&expected), "{json}");
    let mut hand = case;
    hand.header.tool_version = None;
    let json = hand.to_json().unwrap();
    assert!(!json.contains("tool_version"), "{json}");
}

#[test]
fn the_runtime_constants_are_written_in_milliseconds() {
    let safety = crate::files::SafetyConfigRecord::from(SafetyConfig::default());
    assert_eq!(
        serde_json::to_string(&safety).unwrap(),
        r#"{"area_margin_m":0.3,"max_cross_track_m":1.5,"stale_after":500}"#
    );
    assert_eq!(SafetyConfig::from(safety), SafetyConfig::default());
    let streaming = crate::files::StreamingConfigRecord::from(StreamingConfig::default());
    assert_eq!(
        serde_json::to_string(&streaming).unwrap(),
        r#"{"margin":1000,"initial_round_trip":500,"initial_generation":100,"window":200,"min_speed_mps":0.1}"#
    );
    assert_eq!(StreamingConfig::from(streaming), StreamingConfig::default());
    let append = Append {
        decided_at: std::time::Duration::from_millis(1000),
        time_to_end: std::time::Duration::from_millis(2400),
        lead: std::time::Duration::from_millis(1700),
        confirmed_after: Some(std::time::Duration::from_millis(180)),
    };
    let record = AppendRecord::from(append);
    assert_eq!(
        serde_json::to_string(&record).unwrap(),
        r#"{"decided_at":1000,"time_to_end":2400,"lead":1700,"confirmed_after":180}"#
    );
    assert_eq!(record.margin_left_s(), append.margin_left_s());
}

#[test]
fn the_fault_sections_are_recorded_whole_and_the_flat_form_still_loads() {
    let examples = doc_examples();
    let current = CampaignRecord::from_json(examples[2]).unwrap();
    assert_eq!(current.header.schema_version, CAMPAIGN_SCHEMA_VERSION);
    let s = scenario("parking-lot-2anchors");
    let written = Settings::new(&s, 10, FailurePolicy::default());
    let crate::files::FaultRangesForm::Sections(sections) = &current.settings.faults else {
        panic!(
            "the current example holds the sections: {:?}",
            current.settings.faults
        );
    };
    assert_eq!(current.settings.faults, written.faults);
    for section in [&sections.anchor_range, &sections.wheel_slip, &sections.yaw] {
        for kind in [
            FaultKind::Offset,
            FaultKind::Amplification,
            FaultKind::SetTo,
            FaultKind::Bitflip,
        ] {
            assert!(section.ranges.contains_key(&kind), "{kind:?}");
        }
    }
    assert_eq!(
        sections.wheel_slip.kinds,
        s.campaign.faults.wheel_slip.kinds
    );
    assert_eq!(
        sections.yaw.ranges[&FaultKind::SetTo],
        s.campaign.faults.yaw.range(FaultKind::SetTo)
    );

    let old = CampaignRecord::from_json(examples[3]).unwrap();
    assert_eq!(old.header.schema_version, 1);
    let crate::files::FaultRangesForm::Flat(flat) = &old.settings.faults else {
        panic!("the version-1 example holds the flat form");
    };
    assert_eq!(flat.anchor_range_param, scenarios::Interval::new(0.0, 5.0));
}

#[test]
fn a_file_must_hold_the_fault_ranges_of_its_version() {
    let examples = doc_examples();
    let flat_as_new = examples[3].replacen("\"schema_version\": 1", "\"schema_version\": 2", 1);
    let error = CampaignRecord::from_json(&flat_as_new)
        .unwrap_err()
        .to_string();
    assert!(
        error.starts_with("settings.faults: the flat fault ranges"),
        "{error}"
    );
    let sections_as_old = examples[2].replacen("\"schema_version\": 2", "\"schema_version\": 1", 1);
    let error = CampaignRecord::from_json(&sections_as_old)
        .unwrap_err()
        .to_string();
    assert!(
        error.starts_with("settings.faults: fault sections"),
        "{error}"
    );

    let (_, case) = run_case();
    let json = case.to_json().unwrap();
    assert!(json.contains("\"wheel_slip\": {"), "{json}");
    let as_v2 = json.replacen("\"schema_version\": 3", "\"schema_version\": 2", 1);
    let error = Case::from_json(&as_v2).unwrap_err().to_string();
    assert!(
        error.starts_with("settings.faults: fault sections"),
        "{error}"
    );

    let neither = examples[2].replacen("\"wheel_slip\": {", "\"wheel_slip_x\": {", 1);
    let error = CampaignRecord::from_json(&neither).unwrap_err().to_string();
    assert!(
        error.starts_with("settings.faults:") && error.contains("`anchor_range`, `wheel_slip`"),
        "{error}"
    );
}
