//! A campaign on several cars (`run --car A=… --car B=…`), end to end: two `drivecheck sim` cars
//! over TCP in real time, the live view showing both, one car's simulator killed in the middle of
//! its test: the other car drives that test again and the campaign ends with every test once and
//! the lost car named. (That two cars take about half the time of one is measured in virtual time
//! by `runner/src/lab.rs`'s tests, and in real time in docs/scaling.md.)

use crate::common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{drivecheck, path, start_sim, text};
use futures::StreamExt;
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

/// The topics the live view at `port` advertises within `within`.
async fn advertised(port: u16, within: Duration) -> Vec<String> {
    let mut topics = Vec::new();
    let _ = tokio::time::timeout(within, async {
        let mut request = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        request.headers_mut().insert(
            "sec-websocket-protocol",
            "foxglove.websocket.v1".parse().unwrap(),
        );
        let mut socket = loop {
            match tokio_tungstenite::connect_async(request.clone()).await {
                Ok((socket, _)) => break socket,
                Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
            }
        };
        while let Some(Ok(message)) = socket.next().await {
            if let Message::Text(text) = message {
                let json: Value = serde_json::from_str(&text).unwrap();
                if json["op"] == "advertise" {
                    for channel in json["channels"].as_array().unwrap() {
                        topics.push(channel["topic"].as_str().unwrap().to_owned());
                    }
                }
            }
        }
    })
    .await;
    topics
}

/// Car A drives one test, car B is lost in the other, A drives it again (short tests: about
/// 30 s of wall time).
#[test]
fn a_car_lost_mid_test_leaves_and_the_campaign_ends_on_the_other_with_every_test_once() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = common::short_tests(tmp.path());
    let (mut sim_a, a) = common::start_sim_with(tmp.path(), "a", path(&scenario), &[], 10);
    let (mut sim_b, b) = common::start_sim_with(tmp.path(), "b", path(&scenario), &[], 10);
    let out = tmp.path().join("run");
    let mut run = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "run",
            "--scenario",
            path(&scenario),
            "--seed",
            "3",
            "--tests",
            "2",
            "--report",
            "--out",
            path(&out),
        ])
        .args(["--car", &format!("A={a}"), "--car", &format!("B={b}")])
        // Port 0: the campaign binds a free port and says which (a port chosen here and freed
        // could be taken by another test's server before the campaign binds it).
        .args(["--live", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = run.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    let (port_tx, port_rx) = mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut said = String::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.contains("started on car B") {
                let _ = tx.send(Instant::now());
            }
            if let Some(port) = common::live_port(&line) {
                let _ = port_tx.send(port);
            }
            said.push_str(&line);
            said.push('\n');
        }
        said
    });
    let port = port_rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the campaign never said its live view's port");
    let topics = tokio::runtime::Runtime::new()
        .unwrap()
        .block_on(advertised(port, Duration::from_secs(5)));
    // B is in its test's reset or drive: its simulator dies.
    let started = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("car B never started a test");
    // A short test and its reset take about 12 s: 3 s in (or at once, if the live view's
    // topics took longer), B is still driving it.
    std::thread::sleep(
        (started + Duration::from_secs(3)).saturating_duration_since(Instant::now()),
    );
    let _ = (sim_b.kill(), sim_b.wait());
    let output = run.wait_with_output().unwrap();
    let _ = (sim_a.kill(), sim_a.wait());
    let said = reader.join().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{said}\n{stdout}"
    );
    for car in ["A", "B"] {
        for topic in ["car/state", "foxglove/rtk", "foxglove/uwb"] {
            let topic = format!("/{car}/{topic}");
            assert!(topics.contains(&topic), "{topic} not in {topics:?}");
        }
    }
    assert!(topics.contains(&"/foxglove/area".to_owned()), "{topics:?}");
    assert!(said.contains("car B left the campaign"), "{said}");
    assert!(stdout.contains("car B (tcp://"), "{stdout}");
    assert!(
        stdout.contains("LEFT the campaign after 0 tests"),
        "{stdout}"
    );
    assert!(stdout.contains("| test | car | verdict |"), "{stdout}");
    assert!(stdout.contains("| 0 | A | "), "{stdout}");
    let record: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(record["summary"]["tests"], 2, "{record}");
    let cars = record["cars"].as_array().unwrap();
    assert_eq!(cars[0]["name"], "A");
    assert_eq!(cars[0]["tests"].as_array().unwrap().len(), 2, "{record}");
    assert!(cars[0].get("left").is_none(), "{record}");
    assert_eq!(cars[1]["name"], "B");
    assert!(
        cars[1]["left"].as_str().unwrap().contains("link"),
        "{record}"
    );
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("case-"))
        .collect();
    names.sort();
    assert_eq!(names.len(), 3, "{names:?}");
    let partial = names.iter().find(|n| n.contains(".partial-1")).unwrap();
    let case = |name: &str| -> Value {
        serde_json::from_str(&std::fs::read_to_string(out.join(name)).unwrap()).unwrap()
    };
    assert_eq!(case(partial)["car"], "B");
    for name in ["case-000.json", "case-001.json"] {
        assert_eq!(case(name)["car"], "A", "{name}");
    }
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        report.contains("<b>left the campaign</b>: test "),
        "the report names the lost car"
    );
    let recording = recording::Recording::read(&out.join("campaign.mcap")).unwrap();
    assert!(recording.is_complete());
}

/// Cars that cannot drive one campaign together are refused before anything connects, naming
/// the `--car` at fault; nothing is written.
#[test]
fn cars_that_cannot_share_a_campaign_are_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let refused = |cars: &[&str], extra: &[&str], says: &str| {
        let mut args = vec!["run", "--tests", "1", "--out", path(&out)];
        for car in cars {
            args.extend(["--car", car]);
        }
        args.extend(extra);
        let ran = drivecheck(&args);
        assert_eq!(ran.status.code(), Some(2), "{}", text(&ran));
        assert!(text(&ran).contains(says), "{}", text(&ran));
        assert!(!out.exists());
    };
    let (a, b) = ("tcp://127.0.0.1:9", "tcp://127.0.0.1:10");
    refused(
        &["sim", b],
        &[],
        "--car sim: the embedded simulated car gives every test a fresh car already",
    );
    refused(
        &[&format!("x={a}"), &format!("x={b}")],
        &[],
        "the name x is already the car at",
    );
    refused(&[a, a], &[], "is already car car1");
    refused(
        &[a, b],
        &["--jobs", "2"],
        "several cars drive their tests at once already",
    );
    refused(&["a b=tcp://x:1", b], &[], "--car a b=tcp://x:1");
}

/// `run --dry-run --json` with several cars checks each and prints one document naming them.
#[test]
fn a_dry_run_of_several_cars_is_one_json_document() {
    let tmp = tempfile::tempdir().unwrap();
    let (mut sim_a, a) = start_sim(tmp.path(), "a");
    let (mut sim_b, b) = start_sim(tmp.path(), "b");
    let output = drivecheck(&[
        "run",
        "--dry-run",
        "--json",
        "--car",
        &format!("A={a}"),
        "--car",
        &format!("B={b}"),
    ]);
    for sim in [&mut sim_a, &mut sim_b] {
        let _ = (sim.kill(), sim.wait());
    }
    assert_eq!(output.status.code(), Some(0), "{}", text(&output));
    let document: Value =
        serde_json::from_slice(&output.stdout).unwrap_or_else(|e| panic!("{e}: {}", text(&output)));
    assert_eq!(document["command"], "run --dry-run");
    let cars = document["cars"].as_array().expect("cars");
    let named: Vec<(&str, &str)> = cars
        .iter()
        .map(|c| (c["name"].as_str().unwrap(), c["address"].as_str().unwrap()))
        .collect();
    assert_eq!(named, [("A", a.as_str()), ("B", b.as_str())]);
    for car in cars {
        assert!(
            car["firmware"].is_string() && car["route_points"].as_u64() > Some(0),
            "{car}"
        );
    }
}

/// The firmware built for the host served like a car (`drivecheck sim --car sitl:TREE`): a dry
/// run passes against it over TCP in real time (the firmware's own preflight answers, its route
/// and faults read back), and again for a second client after the first left — one firmware.
#[test]
fn the_firmware_served_over_tcp_passes_a_dry_run_for_one_client_after_another() {
    let Some(tree) = std::env::var("DRIVECHECK_FIRMWARE_10")
        .ok()
        .filter(|v| !v.is_empty())
    else {
        common::skipped("firmware", "no firmware tree (DRIVECHECK_FIRMWARE_10)");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let car = format!("sitl:{tree}");
    let (mut sim, address) = common::start_sim_with(
        tmp.path(),
        "fw",
        "parking-lot-2anchors",
        &["--car", &car],
        120,
    );
    for client in 1..=2 {
        let out = drivecheck(&["run", "--dry-run", "--car", &address]);
        let said = text(&out);
        assert_eq!(out.status.code(), Some(0), "client {client}: {said}");
        assert!(said.contains("firmware 10.1"), "client {client}: {said}");
    }
    let _ = (sim.kill(), sim.wait());
}
