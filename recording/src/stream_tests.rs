//! Tests of reading a recording from its file as a stream: the same spans as from its bytes, what
//! a file cut short holds before the damage, and a recording's summary without its messages.

use std::path::Path;
use std::time::Duration;

use scenarios::Scenario;
use tokio::time::Instant;

use super::*;
use campaign::files::{
    CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION, CampaignRecord, Header, ScenarioRef, Settings,
};
use campaign::oracle::FailurePolicy;

const TESTS: usize = 12;

fn scenario() -> Scenario {
    scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario
}

/// A recording of `TESTS` tests with a span each (three chunks of messages per test), as a
/// campaign on fresh simulated cars writes it.
fn spanned_recording(path: &Path) {
    let s = scenario();
    let campaign = CampaignRecord {
        header: Header::current(CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION),
        seed: 42,
        no_faults: false,
        scenario: ScenarioRef::of(&s),
        settings: Settings::new(&s, TESTS, FailurePolicy::default()),
        car: "sim".to_owned(),
        car_profile: None,
        car_firmware_version: None,
        car_firmware_tree_hash: None,
        started_at: "2026-11-22T10:55:21Z".to_owned(),
        ended_at: None,
        summary: None,
        replay_of: None,
        cases_from: None,
        shard: None,
        sessions: Vec::new(),
        cars: Vec::new(),
    };
    let origin = Instant::now();
    let start = RecordingStart {
        campaign: &campaign,
        scenario: &s,
        origin,
        simulated: true,
        chunk_interval: DEFAULT_CHUNK_INTERVAL,
        live: None,
        test_spans: true,
        sim_profile: None,
    };
    let mut recorder = Recorder::create(path, &start).unwrap();
    for test_index in 0..TESTS {
        let start_ms = 1_000 * test_index as u64 + 1;
        for k in 0..6 {
            let event = TestEvent {
                test_index,
                event: TestEventKind::Started { commands: k },
            };
            let at = origin + Duration::from_millis(start_ms + 10 * k as u64);
            recorder.write_at(at, &event).unwrap();
            if k % 2 == 1 {
                recorder.flush().unwrap();
            }
        }
        let ns = |ms: u64| ms * 1_000_000;
        recorder
            .test_span(test_index, ns(start_ms), ns(start_ms + 50), None)
            .unwrap();
    }
    recorder.finish().unwrap();
}

/// What a reading of spans gave, errors in words.
fn taken<R: std::io::Read>(spans: Spans<R>) -> Vec<Result<Span, String>> {
    spans.map(|s| s.map_err(|e| e.to_string())).collect()
}

#[tokio::test(start_paused = true)]
async fn spans_read_from_the_file_are_the_spans_of_its_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    spanned_recording(&path);
    let bytes = std::fs::read(&path).unwrap();
    let from_bytes = taken(Spans::new(&bytes).unwrap());
    let from_file = taken(Spans::open(&path).unwrap());
    assert_eq!(from_file, from_bytes);
    let tests: Vec<Option<usize>> = from_file
        .iter()
        .map(|s| s.as_ref().unwrap().test_index)
        .collect();
    assert_eq!(tests, (0..TESTS).map(Some).collect::<Vec<_>>());
    // Six test events each (and the route's clearing Foxglove gets with a test's start).
    let events = |span: &Span| {
        let tests = span.messages.iter().filter(|m| m.topic() == Topic::Tests);
        tests.count()
    };
    assert!(from_file.iter().all(|s| events(s.as_ref().unwrap()) == 6));
    // The metadata records read on the way.
    let mut spans = Spans::open(&path).unwrap();
    assert!(spans.metadata("drivecheck.campaign").is_none());
    spans.next().unwrap().unwrap();
    assert_eq!(spans.metadata("drivecheck.campaign").unwrap()["seed"], "42");
}

#[tokio::test(start_paused = true)]
async fn one_tests_span_is_read_from_its_place_as_reading_the_whole_file_gives_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    spanned_recording(&path);
    let whole = taken(Spans::open(&path).unwrap());
    // The first test has no span record before it: read from the start.
    assert!(Spans::open_test(&path, 0).unwrap().is_none());
    assert!(Spans::open_test(&path, TESTS).unwrap().is_none());
    for (test, span) in whole.iter().enumerate().skip(1) {
        let spans = Spans::open_test(&path, test).unwrap().expect("indexed");
        assert_eq!(
            spans.metadata("drivecheck.campaign").unwrap()["seed"],
            "42",
            "test {test}"
        );
        assert_eq!(taken(spans), std::slice::from_ref(span), "test {test}");
    }
    // A file without its summary section (a campaign that did not finish) is read whole.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let last = summary.chunk_indexes.last().unwrap();
    let data_end = usize::try_from(last.chunk_start_offset + last.chunk_length).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..data_end]).unwrap();
    assert!(Spans::open_test(&cut, 5).unwrap().is_none());
    // A metadata index that points elsewhere than at a metadata record is not followed.
    let mut moved = bytes.clone();
    let campaign_at = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == "drivecheck.campaign")
        .map(|m| usize::try_from(m.offset).unwrap())
        .unwrap();
    moved[campaign_at] ^= 0xff;
    std::fs::write(&cut, &moved).unwrap();
    assert!(Spans::open_test(&cut, 5).unwrap().is_none());
}

#[tokio::test(start_paused = true)]
async fn a_file_cut_short_gives_the_spans_before_the_damage_then_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    spanned_recording(&path);
    let bytes = std::fs::read(&path).unwrap();
    let whole = taken(Spans::new(&bytes).unwrap());
    let cut = dir.path().join("cut.mcap");
    let mut before = 0;
    for length in (0..bytes.len()).step_by(53) {
        std::fs::write(&cut, &bytes[..length]).unwrap();
        let read = taken(Spans::open(&cut).unwrap());
        let (last, spans) = read.split_last().unwrap();
        assert!(
            last.is_err(),
            "a {length}-byte prefix ended without an error"
        );
        assert!(spans.iter().all(Result::is_ok), "{length} bytes: {read:?}");
        assert_eq!(spans, &whole[..spans.len()], "{length} bytes");
        assert!(
            spans.len() >= before,
            "{length} bytes: fewer spans than a shorter prefix"
        );
        before = spans.len();
    }
    // Up to the middle chunk of messages (the summary section, with every channel's schema,
    // is a large part of so small a file): some of the tests, not all.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let chunks = &summary.chunk_indexes;
    let middle = &chunks[chunks.len() / 2];
    let middle_end = usize::try_from(middle.chunk_start_offset + middle.chunk_length).unwrap();
    std::fs::write(&cut, &bytes[..middle_end]).unwrap();
    let read = taken(Spans::open(&cut).unwrap());
    assert!((2..TESTS).contains(&(read.len() - 1)), "{}", read.len());
    // Bytes changed in the middle chunk: the spans before it, then the chunk's CRC.
    let mut damaged = bytes.clone();
    let middle = usize::try_from(middle.chunk_start_offset + middle.chunk_length / 2).unwrap();
    damaged[middle] ^= 0x10;
    std::fs::write(&cut, &damaged).unwrap();
    let read = taken(Spans::open(&cut).unwrap());
    let (last, spans) = read.split_last().unwrap();
    assert!(last.is_err(), "{read:?}");
    assert_eq!(spans, &whole[..spans.len()]);
    assert!(spans.len() < TESTS);
}

#[tokio::test(start_paused = true)]
async fn a_files_summary_says_what_reading_it_whole_says() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign.mcap");
    spanned_recording(&path);
    let whole = Recording::read(&path).unwrap();
    let summary = Summary::read(&path).unwrap();
    assert_eq!(summary, Summary::scan(&path).unwrap());
    assert!(summary.is_complete());
    assert_eq!(summary.messages, whole.message_count() as u64);
    assert!(summary.messages > 6 * TESTS as u64);
    // Cut short, or damaged in its summary: scanned, and what the whole reading says.
    let bytes = std::fs::read(&path).unwrap();
    let footer_at = bytes.len() - 37;
    let summary_start =
        u64::from_le_bytes(bytes[footer_at + 9..footer_at + 17].try_into().unwrap()) as usize;
    let mut in_summary = bytes.clone();
    in_summary[summary_start + 20] ^= 0x01;
    let damaged = dir.path().join("damaged.mcap");
    let prefixes = [bytes.len() / 3, bytes.len() - 1, summary_start + 5];
    let files = prefixes
        .iter()
        .map(|&length| bytes[..length].to_vec())
        .chain([in_summary]);
    for file in files {
        std::fs::write(&damaged, &file).unwrap();
        let whole = Recording::from_bytes(&file).unwrap();
        let summary = Summary::read(&damaged).unwrap();
        assert_eq!(summary, Summary::scan(&damaged).unwrap());
        assert!(!summary.is_complete());
        assert_eq!(summary.cut_short(), whole.cut_short());
        assert!(summary.cut_short().is_some());
        assert_eq!(summary.messages, whole.message_count() as u64);
    }
    // Not a recording at all.
    std::fs::write(&damaged, b"{\"format\": \"drivecheck-case\"}").unwrap();
    assert!(matches!(
        Summary::read(&damaged),
        Err(RecordingError::NotMcap(_))
    ));
    assert!(matches!(
        Summary::read(&dir.path().join("absent.mcap")),
        Err(RecordingError::Read { .. })
    ));
}
