//! `drivecheck run --live`: a WebSocket client speaking the Foxglove protocol subscribes to the
//! area and the car's RTK poses and receives them while the campaign runs, whichever of the
//! protocol's two subprotocol names it offers, and however late it joins.

use crate::common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use common::path;
use futures::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

/// Runs a campaign with `--live` (and `extra` options), connects `join_after` into it offering
/// `subprotocol`, subscribes to the area and the RTK poses, and returns the first area and the
/// first pose.
async fn watch(
    subprotocol: &str,
    join_after: Duration,
    extra: &[&str],
) -> (serde_json::Value, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    // Port 0: the campaign binds a free port and says which; a port chosen here and freed
    // before the campaign binds it could be taken by another test's server in between.
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["run", "--tests", "2", "--seed", "1", "--out", path(&out)])
        .args(extra)
        .args(["--live", "127.0.0.1:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (port_tx, port_rx) = std::sync::mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(port) = common::live_port(&line) {
                let _ = port_tx.send(port);
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let Ok(port) = port_rx.recv_timeout(Duration::from_secs(60)) else {
        let _ = child.kill();
        let _ = child.wait();
        panic!("no live view: {}", stderr.join().unwrap());
    };
    tokio::time::sleep(join_after).await;
    let received = tokio::time::timeout(Duration::from_secs(60), async {
        let mut request = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        request
            .headers_mut()
            .insert("sec-websocket-protocol", subprotocol.parse().unwrap());
        let mut socket = loop {
            match tokio_tungstenite::connect_async(request.clone()).await {
                Ok((socket, response)) => {
                    // The server answers with the name the client offered.
                    assert_eq!(
                        response.headers()["sec-websocket-protocol"],
                        subprotocol,
                        "{response:?}"
                    );
                    break socket;
                }
                Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
            }
        };
        let (mut area, mut pose) = (None, None);
        // What the view said, for a failure's message.
        let mut advertised: Vec<String> = Vec::new();
        let mut subscribed: Vec<u32> = Vec::new();
        // The server's other text messages (a status saying a subscription was refused, …).
        let mut said: Vec<String> = Vec::new();
        let seen =
            |advertised: &[String], subscribed: &[u32], said: &[String], area: bool, pose: bool| {
                format!(
                    "advertised {advertised:?}, subscribed {subscribed:?}, an area {}, a pose {}; \
                 the server also said {said:?}",
                    if area { "came" } else { "did not come" },
                    if pose { "came" } else { "did not come" },
                )
            };
        while let Some(message) = socket.next().await {
            let message = message.map_err(|e| {
                format!(
                    "the live view failed: {e}; {}",
                    seen(
                        &advertised,
                        &subscribed,
                        &said,
                        area.is_some(),
                        pose.is_some()
                    )
                )
            })?;
            match message {
                Message::Text(text) => {
                    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                    if json["op"] != "advertise" {
                        if json["op"] != "serverInfo" {
                            said.push(text.to_string());
                        }
                        continue;
                    }
                    for channel in json["channels"].as_array().unwrap() {
                        advertised.push(channel["topic"].as_str().unwrap_or("?").to_owned());
                        let id = match channel["topic"].as_str() {
                            Some("/foxglove/area") => 1,
                            Some("/foxglove/rtk") => {
                                assert_eq!(channel["schemaName"], "foxglove.PoseInFrame");
                                assert_eq!(channel["encoding"], "protobuf");
                                assert_eq!(channel["schemaEncoding"], "protobuf");
                                2
                            }
                            _ => continue,
                        };
                        subscribed.push(id);
                        let subscribe = serde_json::json!({
                            "op": "subscribe",
                            "subscriptions": [{"id": id, "channelId": channel["id"]}],
                        });
                        socket
                            .send(Message::Text(subscribe.to_string().into()))
                            .await
                            .unwrap();
                    }
                }
                Message::Binary(data) if data.first() == Some(&1) => {
                    let subscription = u32::from_le_bytes(data[1..5].try_into().unwrap());
                    let message = match subscription {
                        // The poses are Foxglove's protobuf `PoseInFrame`.
                        2 => pose_json(&data[13..]),
                        _ => serde_json::from_slice(&data[13..]).unwrap(),
                    };
                    match subscription {
                        1 => area = area.or(Some(message)),
                        2 => pose = pose.or(Some(message)),
                        other => panic!("subscription {other}"),
                    }
                    if let (Some(area), Some(pose)) = (&area, &pose) {
                        return Ok((area.clone(), pose.clone()));
                    }
                }
                _ => {}
            }
        }
        Err(format!(
            "the live view closed before the area and a pose came; {}",
            seen(
                &advertised,
                &subscribed,
                &said,
                area.is_some(),
                pose.is_some()
            )
        ))
    })
    .await
    .unwrap_or_else(|_| Err("no area and pose within 60 s".to_owned()));
    // Whether the campaign had already ended, for the message.
    let ended = child.try_wait().unwrap();
    let _ = child.kill();
    let _ = child.wait();
    let stderr = stderr.join().unwrap();
    received.unwrap_or_else(|why| {
        panic!(
            "{why} (the campaign {}): {}",
            match ended {
                Some(status) => format!("had ended, {status}"),
                None => "was still running".to_owned(),
            },
            stderr
        )
    })
}

/// A `foxglove.PoseInFrame` in protobuf, as the JSON of its frame and position.
fn pose_json(data: &[u8]) -> serde_json::Value {
    let pose: foxglove::messages::PoseInFrame = prost::Message::decode(data).unwrap();
    let position = pose.pose.and_then(|p| p.position).unwrap();
    serde_json::json!({
        "frame_id": pose.frame_id,
        "pose": {"position": {"x": position.x, "y": position.y}},
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_subscribes_and_receives_the_area_and_poses_while_the_campaign_runs() {
    let (area, pose) = watch("foxglove.sdk.v1", Duration::ZERO, &[]).await;
    assert!(area["entities"].is_array(), "{area}");
    assert_eq!(pose["frame_id"], "map");
    assert!(pose["pose"]["position"]["x"].is_number(), "{pose}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lichtblick_client_joining_five_seconds_late_still_gets_the_area() {
    // Lichtblick and `@foxglove/ws-protocol` offer only the specification's name.
    let (area, pose) = watch("foxglove.websocket.v1", Duration::from_secs(5), &[]).await;
    assert!(area["entities"].is_array(), "{area}");
    assert!(pose["pose"]["position"]["x"].is_number(), "{pose}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_campaign_that_records_nothing_still_serves_the_area_and_poses_live() {
    // `--record none` keeps no `campaign.mcap`; the live view is served all the same.
    let (area, pose) = watch(
        "foxglove.sdk.v1",
        Duration::from_secs(2),
        &["--record", "none"],
    )
    .await;
    assert!(area["entities"].is_array(), "{area}");
    assert!(pose["pose"]["position"]["x"].is_number(), "{pose}");
}
