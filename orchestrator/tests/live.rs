//! `drivecheck run --live`: a WebSocket client speaking the Foxglove protocol subscribes to the
//! car's RTK poses and receives them while the campaign runs.

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::path;
use futures::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_subscribes_and_receives_poses_while_the_campaign_runs() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["run", "--tests", "1", "--seed", "1", "--out", path(&out)])
        .arg("--live")
        .arg(format!("127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let received = tokio::time::timeout(Duration::from_secs(60), async {
        let mut request = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        request
            .headers_mut()
            .insert("sec-websocket-protocol", "foxglove.sdk.v1".parse().unwrap());
        let mut socket = loop {
            match tokio_tungstenite::connect_async(request.clone()).await {
                Ok((socket, _)) => break socket,
                Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
            }
        };
        let mut subscribed = false;
        while let Some(message) = socket.next().await {
            match message.unwrap() {
                Message::Text(text) if !subscribed => {
                    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                    if json["op"] != "advertise" {
                        continue;
                    }
                    let Some(channel) = json["channels"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|c| c["topic"] == "/foxglove/rtk")
                    else {
                        continue;
                    };
                    assert_eq!(channel["schemaName"], "foxglove.PoseInFrame");
                    let subscribe = serde_json::json!({
                        "op": "subscribe",
                        "subscriptions": [{"id": 7, "channelId": channel["id"]}],
                    });
                    socket
                        .send(Message::Text(subscribe.to_string().into()))
                        .await
                        .unwrap();
                    subscribed = true;
                }
                Message::Binary(data) if subscribed && data.first() == Some(&1) => {
                    let subscription = u32::from_le_bytes(data[1..5].try_into().unwrap());
                    assert_eq!(subscription, 7);
                    let pose: serde_json::Value = serde_json::from_slice(&data[13..]).unwrap();
                    return pose;
                }
                _ => {}
            }
        }
        panic!("the live view closed before a pose came");
    })
    .await;
    let _ = child.kill();
    let output = child.wait_with_output().unwrap();
    let pose = received.unwrap_or_else(|_| {
        panic!(
            "no pose within 60 s: {}",
            String::from_utf8_lossy(&output.stderr)
        )
    });
    assert_eq!(pose["frame_id"], "map");
    assert!(pose["pose"]["position"]["x"].is_number(), "{pose}");
}
