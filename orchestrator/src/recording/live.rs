//! The live view (`drivecheck run --live`): every channel of the recording, served while the
//! campaign runs over the Foxglove WebSocket protocol by the official `foxglove` crate, so an
//! operator watches the area, the planned route, the car and its UWB estimate in Foxglove (*Open
//! connection…*, `ws://ADDR`) on a laptop. The messages are the very JSON the recording holds.

use std::collections::HashMap;
use std::fmt;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use foxglove::{
    ChannelBuilder, Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};

use super::topic::Topic;

/// Where the live view's channels go: a `foxglove` context served by a WebSocket server.
#[derive(Clone)]
pub struct LiveView {
    context: Arc<Context>,
    /// The channels made so far: every recorder of the campaign (one per test when tests run on
    /// fresh simulated cars) logs to the same channel of a topic.
    channels: Arc<Mutex<HashMap<Topic, Arc<RawChannel>>>>,
}

impl fmt::Debug for LiveView {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("LiveView")
    }
}

impl PartialEq for LiveView {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.context, &other.context)
    }
}

/// Why the live view could not start.
#[derive(Debug, thiserror::Error)]
#[error("cannot serve the live view on {addr}: {message}")]
pub struct LiveError {
    /// The address asked for.
    pub addr: SocketAddr,
    /// What the server said.
    pub message: String,
}

impl LiveView {
    /// Starts a WebSocket server on `addr` (port 0: any free port); the view and the server's
    /// handle, which serves until it is stopped or dropped with the runtime. Call it inside the
    /// runtime.
    pub async fn start(addr: SocketAddr) -> Result<(Self, WebSocketServerHandle), LiveError> {
        let context = Context::new();
        let server = WebSocketServer::new()
            .name("drivecheck")
            .bind(addr.ip().to_string(), addr.port())
            .context(&context)
            .start()
            .await
            .map_err(|e| LiveError {
                addr,
                message: e.to_string(),
            })?;
        Ok((
            Self {
                context,
                channels: Arc::default(),
            },
            server,
        ))
    }

    /// A channel of the view for `topic`, with its schema.
    pub(super) fn channel(&self, topic: Topic, schema: &str) -> Option<Arc<RawChannel>> {
        let mut channels = self.channels.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(channel) = channels.get(&topic) {
            return Some(Arc::clone(channel));
        }
        let channel = ChannelBuilder::new(topic.name())
            .message_encoding("json")
            .schema(Schema::new(
                topic.schema_name(),
                "jsonschema",
                schema.as_bytes().to_vec(),
            ))
            .context(&self.context)
            .build_raw()
            .ok()?;
        channels.insert(topic, Arc::clone(&channel));
        Some(channel)
    }
}
