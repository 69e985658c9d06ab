//! The live view (`drivecheck run --live`): every channel of the recording, served while the
//! campaign runs over the Foxglove WebSocket protocol by the official `foxglove` crate, so an
//! operator watches the area, the planned route, the car and its UWB estimate in Foxglove (*Open
//! connection…*, `ws://ADDR`) on a laptop. The messages are the very JSON the recording holds.

use std::collections::HashMap;
use std::fmt;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{
    ChannelBuilder, ChannelId, Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use super::topic::Topic;

/// The WebSocket subprotocol of the `foxglove` crate's server.
const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// The subprotocol of the Foxglove WebSocket protocol's specification, the only one Lichtblick,
/// older Foxglove Studio and `@foxglove/ws-protocol` clients offer. The two are the same
/// protocol under two names (foxglove/ws-protocol and Lichtblick PR #819 say so).
const WS_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The largest HTTP upgrade request the live view reads.
const MAX_HANDSHAKE: usize = 16 * 1024;
/// The largest message a viewer may send, bytes (all its fragments): a viewer sends only small
/// control messages (subscribe, unsubscribe: a few dozen bytes a channel), and the server would
/// buffer whatever it is sent (a viewer sending 16 MB messages cost 40 MB of memory, #51). A
/// viewer that sends more is disconnected (a close frame with status 1009, *message too big*).
pub const MAX_VIEWER_MESSAGE: u64 = 64 * 1024;

/// Where the live view's channels go: a `foxglove` context served by a WebSocket server.
#[derive(Clone)]
pub struct LiveView {
    context: Arc<Context>,
    /// The channels made so far, by car (`""` for a campaign on one car) and topic: every
    /// recorder of the campaign (one per test when tests run on fresh simulated cars) logs to
    /// the same channel of a topic.
    channels: Arc<Mutex<HashMap<(String, Topic), LiveChannel>>>,
    /// The car whose channels this view makes (see [`LiveView::for_car`]); empty for one car.
    car: String,
    /// The last message of every latched channel, by channel id.
    latched: Latched,
}

/// The last message of the channels a viewer that joins late must still see (the area, the
/// route): sent to each new subscriber alone.
type Latched = Arc<Mutex<HashMap<ChannelId, (Arc<RawChannel>, Vec<u8>)>>>;

/// A channel of the live view.
#[derive(Clone)]
pub(super) struct LiveChannel {
    raw: Arc<RawChannel>,
    /// The view's latched messages (see [`LiveChannel::repeat_latched`]).
    latched: Latched,
    /// Whether this channel's last message is kept for viewers that subscribe later.
    keeps_last: bool,
}

impl LiveChannel {
    /// Serves `data` to every subscriber (and keeps it for those that subscribe later, if the
    /// topic is latched).
    pub(super) fn log(&self, data: &[u8]) {
        if !self.keeps_last {
            self.raw.log(data);
            return;
        }
        // Sent and kept under one lock, the lock [`LateJoiner`] sends under: a viewer that
        // subscribes at this very moment gets the message either as a subscriber or as a late
        // joiner, never neither.
        let mut latched = self.latched.lock().unwrap_or_else(|e| e.into_inner());
        self.raw.log(data);
        latched.insert(self.raw.id(), (Arc::clone(&self.raw), data.to_vec()));
    }

    /// Serves the kept message of every latched channel (the area, each car's route) again, to
    /// every subscriber. The recorder does so as each test starts and ends: the area is made
    /// once a campaign, and a viewer that did not get it (the foxglove server drops a viewer's
    /// oldest messages when its outbox is full, and a CI run once saw a viewer subscribed to the
    /// area get poses for a whole campaign and no area) has it again within a test.
    pub(super) fn repeat_latched(&self) {
        let latched = self.latched.lock().unwrap_or_else(|e| e.into_inner());
        for (raw, data) in latched.values() {
            raw.log(data);
        }
    }
}

/// Sends a latched channel's last message to a client as it subscribes.
struct LateJoiner {
    latched: Latched,
}

impl ServerListener for LateJoiner {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        // The server has made the client a subscriber before it calls this: a message logged
        // from now on reaches it; one logged before is the one kept here (see
        // [`LiveChannel::log`]).
        let latched = self.latched.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((raw, data)) = latched.get(&channel.id()) {
            raw.log_to_sink(data, client.sink_id());
        }
    }
}

/// The live view's server: the `foxglove` crate's WebSocket server behind a front door that
/// speaks both subprotocols.
pub struct LiveServer {
    /// The crate's server, on a loopback port of its own.
    _inner: WebSocketServerHandle,
    front: tokio::task::JoinHandle<()>,
    port: u16,
}

impl LiveServer {
    /// The port viewers connect to.
    pub fn port(&self) -> u16 {
        self.port
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.front.abort();
    }
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
    /// Starts a WebSocket server on `addr` (port 0: any free port); the view and the server,
    /// which serves until it is dropped (or the runtime is). Viewers offering either subprotocol
    /// (`foxglove.sdk.v1`, `foxglove.websocket.v1`) are served. Call it inside the runtime.
    ///
    /// The channel of every topic the campaign records is made here, the campaign's own and
    /// each of `cars`' (the cars of a campaign on several cars, see [`LiveView::for_car`]), the
    /// simulator's topics too when `simulated`, before a viewer can connect. A channel made
    /// while a viewer is connected races in the `foxglove` crate (0.25; its repository's main of
    /// August 2026 too): the server sends the advertisement before it records that it did, and
    /// a viewer quick to subscribe is told "Unknown channel ID" and never gets the channel (a CI
    /// run lost the area so). The channels advertised as a viewer connects are recorded before
    /// its messages are read. Only a linked car's simulator topics, made when the car turns
    /// out to be a simulator, are still made late.
    pub async fn start(
        addr: SocketAddr,
        cars: &[&str],
        simulated: bool,
    ) -> Result<(Self, LiveServer), LiveError> {
        let failed = |message: String| LiveError { addr, message };
        let context = Context::new();
        let latched: Latched = Arc::default();
        let inner = WebSocketServer::new()
            .name("drivecheck")
            .bind("127.0.0.1", 0)
            .context(&context)
            .listener(Arc::new(LateJoiner {
                latched: Arc::clone(&latched),
            }))
            .start()
            .await
            .map_err(|e| failed(e.to_string()))?;
        let view = Self {
            context,
            channels: Arc::default(),
            latched,
            car: String::new(),
        };
        // The campaign's own channels (with several cars: the area's, `/foxglove/area`, shared),
        // then each car's.
        for car in std::iter::once(&"").chain(cars) {
            let view = view.for_car(car);
            for topic in super::writer::recorded_topics(simulated) {
                view.channel(topic, &super::schema::channel_schema(topic));
            }
        }
        let inner_addr = SocketAddr::from(([127, 0, 0, 1], inner.port()));
        let listener = TcpListener::bind(addr)
            .await
            .map_err(|e| failed(e.to_string()))?;
        let port = listener
            .local_addr()
            .map_err(|e| failed(e.to_string()))?
            .port();
        let front = tokio::spawn(async move {
            while let Ok((client, _)) = listener.accept().await {
                tokio::spawn(async move {
                    // A client that fails its handshake only loses its own connection.
                    let _ = front_door(client, inner_addr).await;
                });
            }
        });
        Ok((
            view,
            LiveServer {
                _inner: inner,
                front,
                port,
            },
        ))
    }

    /// A channel of the view for `topic`, with its schema.
    pub(super) fn channel(
        &self,
        topic: Topic,
        schema: &super::schema::ChannelSchema,
    ) -> Option<LiveChannel> {
        let mut channels = self.channels.lock().unwrap_or_else(|e| e.into_inner());
        let key = (self.car.clone(), topic);
        if let Some(channel) = channels.get(&key) {
            return Some(channel.clone());
        }
        let name = if self.car.is_empty() {
            topic.name().to_owned()
        } else {
            format!("/{}{}", self.car, topic.name())
        };
        let channel = ChannelBuilder::new(name)
            .message_encoding(topic.encoding().name())
            .schema(Schema::new(
                topic.schema_name(),
                schema.encoding,
                schema.data.clone(),
            ))
            .context(&self.context)
            .build_raw()
            .ok()?;
        let channel = LiveChannel {
            raw: channel,
            latched: Arc::clone(&self.latched),
            keeps_last: topic.is_latched(),
        };
        channels.insert(key, channel.clone());
        Some(channel)
    }

    /// The view of car `car` of a campaign on several cars: the same server, its channels named
    /// `/<car>/car/state`, `/<car>/foxglove/rtk`, … so that every car is seen at once (the area
    /// stays `/foxglove/area`, shared: the campaign's recorder, on the view itself, sends it). `car` is a name `run --car` accepted (letters, digits,
    /// `-`, `_`).
    pub fn for_car(&self, car: &str) -> Self {
        Self {
            car: car.to_owned(),
            ..self.clone()
        }
    }
}

/// Serves one viewer's connection: reads its HTTP upgrade request, names the crate's subprotocol
/// where the viewer offered only the specification's, and passes everything through from then
/// on (the server's answer naming the subprotocol the viewer offered).
async fn front_door(mut client: TcpStream, inner: SocketAddr) -> std::io::Result<()> {
    let Some((head, end)) = read_head(&mut client).await? else {
        return Ok(());
    };
    let (request, rest) = head.split_at(end);
    let request = String::from_utf8_lossy(request);
    let (request, renamed) = offer_sdk_subprotocol(&request);
    // What the viewer sent after its request is its first frames: bounded as the rest.
    let mut limit = FrameLimit::default();
    if limit.feed(rest).is_err() {
        return Ok(());
    }
    let mut server = TcpStream::connect(inner).await?;
    server.write_all(request.as_bytes()).await?;
    server.write_all(rest).await?;
    if renamed {
        // The server's answer: its head names the crate's subprotocol; the viewer asked for the
        // specification's name.
        let Some((head, end)) = read_head(&mut server).await? else {
            return Ok(());
        };
        let (answer, rest) = head.split_at(end);
        let answer = String::from_utf8_lossy(answer).replace(SDK_SUBPROTOCOL, WS_SUBPROTOCOL);
        client.write_all(answer.as_bytes()).await?;
        client.write_all(rest).await?;
    }
    let (mut from_viewer, mut to_viewer) = client.into_split();
    let (mut from_server, mut to_server) = server.into_split();
    let upstream = async {
        let mut buf = vec![0u8; 16 * 1024];
        loop {
            let n = from_viewer.read(&mut buf).await?;
            if n == 0 {
                return std::io::Result::Ok(false);
            }
            if limit.feed(&buf[..n]).is_err() {
                return Ok(true);
            }
            to_server.write_all(&buf[..n]).await?;
        }
    };
    let too_big = tokio::select! {
        up = upstream => up?,
        down = tokio::io::copy(&mut from_server, &mut to_viewer) => {
            down?;
            false
        }
    };
    if too_big {
        // Close, status 1009 (message too big); the server's side of the connection is dropped.
        let _ = to_viewer.write_all(&[0x88, 0x02, 0x03, 0xF1]).await;
        let _ = to_viewer.shutdown().await;
    }
    Ok(())
}

/// A viewer's message above [`MAX_VIEWER_MESSAGE`] (or a frame that is no WebSocket frame).
#[derive(Debug, PartialEq, Eq)]
struct TooBig;

/// Follows the WebSocket frames a viewer sends (RFC 6455, section 5.2), as they stream through,
/// and says when a message is larger than [`MAX_VIEWER_MESSAGE`]: nothing of a frame is held
/// but its header.
#[derive(Debug, Default)]
struct FrameLimit {
    /// The header being read.
    header: Vec<u8>,
    /// Payload bytes of the current frame still to come.
    payload_left: u64,
    /// The bytes of the message so far (its fragments).
    message: u64,
}

impl FrameLimit {
    fn feed(&mut self, mut bytes: &[u8]) -> Result<(), TooBig> {
        while !bytes.is_empty() {
            if self.payload_left > 0 {
                let n = self.payload_left.min(bytes.len() as u64);
                self.payload_left -= n;
                bytes = &bytes[usize::try_from(n).unwrap_or(bytes.len())..];
                continue;
            }
            self.header.push(bytes[0]);
            bytes = &bytes[1..];
            if let Some(len) = self.header_done()? {
                let opcode = self.header[0] & 0x0F;
                let fin = self.header[0] & 0x80 != 0;
                self.header.clear();
                if opcode >= 0x8 {
                    // A control frame (close, ping, pong): at most 125 bytes, amid a message.
                    if len > 125 {
                        return Err(TooBig);
                    }
                } else {
                    self.message = if opcode == 0 { self.message + len } else { len };
                    if self.message > MAX_VIEWER_MESSAGE {
                        return Err(TooBig);
                    }
                    if fin {
                        self.message = 0;
                    }
                }
                self.payload_left = len;
            }
        }
        Ok(())
    }

    /// The payload length once the header is complete.
    fn header_done(&self) -> Result<Option<u64>, TooBig> {
        let h = &self.header;
        if h.len() < 2 {
            return Ok(None);
        }
        let masked = h[1] & 0x80 != 0;
        let (extended, len7) = match h[1] & 0x7F {
            126 => (2, None),
            127 => (8, None),
            n => (0, Some(u64::from(n))),
        };
        let total = 2 + extended + if masked { 4 } else { 0 };
        if h.len() < total {
            return Ok(None);
        }
        let len = match len7 {
            Some(n) => n,
            None => h[2..2 + extended]
                .iter()
                .fold(0u64, |acc, b| (acc << 8) | u64::from(*b)),
        };
        Ok(Some(len))
    }
}

/// Reads an HTTP head from `stream`: the bytes read and where the head ends (after its empty
/// line); `None` when the stream ends first or the head is longer than [`MAX_HANDSHAKE`].
async fn read_head(stream: &mut TcpStream) -> std::io::Result<Option<(Vec<u8>, usize)>> {
    let mut head = Vec::new();
    let mut buf = [0u8; 2048];
    loop {
        let n = stream.read(&mut buf).await?;
        if n == 0 || head.len() + n > MAX_HANDSHAKE {
            return Ok(None);
        }
        head.extend_from_slice(&buf[..n]);
        if let Some(end) = head.windows(4).position(|w| w == b"\r\n\r\n") {
            return Ok(Some((head, end + 4)));
        }
    }
}

/// The upgrade request `request` with `foxglove.sdk.v1` offered where the viewer offered only
/// `foxglove.websocket.v1`, and whether it was renamed.
fn offer_sdk_subprotocol(request: &str) -> (String, bool) {
    let mut renamed = false;
    let lines: Vec<String> = request
        .split("\r\n")
        .map(|line| {
            let Some((name, value)) = line.split_once(':') else {
                return line.to_owned();
            };
            let offered: Vec<&str> = value.split(',').map(str::trim).collect();
            if name.trim().eq_ignore_ascii_case("sec-websocket-protocol")
                && offered.contains(&WS_SUBPROTOCOL)
                && !offered.contains(&SDK_SUBPROTOCOL)
            {
                renamed = true;
                format!("{name}: {SDK_SUBPROTOCOL}")
            } else {
                line.to_owned()
            }
        })
        .collect();
    (lines.join("\r\n"), renamed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TestEventKind;

    /// A viewer's frame header: `fin`, `opcode`, masked, and the payload length.
    fn frame(fin: bool, opcode: u8, len: u64) -> Vec<u8> {
        let mut f = vec![if fin { 0x80 } else { 0 } | opcode];
        match len {
            0..=125 => f.push(0x80 | len as u8),
            126..=0xFFFF => {
                f.push(0x80 | 126);
                f.extend_from_slice(&(len as u16).to_be_bytes());
            }
            _ => {
                f.push(0x80 | 127);
                f.extend_from_slice(&len.to_be_bytes());
            }
        }
        f.extend_from_slice(&[1, 2, 3, 4]);
        f
    }

    #[test]
    fn a_viewer_may_send_small_messages_only() {
        let mut limit = FrameLimit::default();
        // A subscribe message, a ping, then a message of two fragments at the limit, fed a byte
        // at a time as a slow connection gives them.
        let mut stream = frame(true, 1, 60);
        stream.extend(vec![b'x'; 60]);
        stream.extend(frame(true, 9, 4));
        stream.extend(b"ping");
        let half = MAX_VIEWER_MESSAGE / 2;
        for (fin, opcode) in [(false, 2), (true, 0)] {
            stream.extend(frame(fin, opcode, half));
            stream.extend(vec![0u8; half as usize]);
        }
        for byte in &stream {
            assert_eq!(limit.feed(std::slice::from_ref(byte)), Ok(()));
        }
        // One byte more in a message, in one frame or over fragments, is too much.
        let mut one = FrameLimit::default();
        assert_eq!(
            one.feed(&frame(true, 2, MAX_VIEWER_MESSAGE + 1)),
            Err(TooBig)
        );
        let mut fragments = FrameLimit::default();
        let mut stream = frame(false, 1, half);
        stream.extend(vec![0u8; half as usize]);
        assert_eq!(fragments.feed(&stream), Ok(()));
        assert_eq!(fragments.feed(&frame(true, 0, half + 1)), Err(TooBig));
        // 16 MB announced: refused at its header, before any of it is read.
        assert_eq!(
            FrameLimit::default().feed(&frame(true, 2, 16 << 20)),
            Err(TooBig)
        );
        assert_eq!(
            FrameLimit::default().feed(&frame(true, 9, 126)),
            Err(TooBig)
        );
    }

    /// A viewer connected to the live view on `port`, offering the `foxglove` crate's
    /// subprotocol.
    async fn connect_viewer(
        port: u16,
    ) -> tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<TcpStream>> {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;

        let mut request = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        request
            .headers_mut()
            .insert("sec-websocket-protocol", SDK_SUBPROTOCOL.parse().unwrap());
        tokio_tungstenite::connect_async(request).await.unwrap().0
    }

    /// A viewer that sends a 16 MB message is disconnected at its header (#51): the server
    /// never buffers it.
    #[tokio::test]
    async fn a_viewer_sending_a_huge_message_is_disconnected() {
        let (_view, server) = LiveView::start(SocketAddr::from(([127, 0, 0, 1], 0)), &[], true)
            .await
            .expect("the live view starts");
        let mut client = TcpStream::connect(("127.0.0.1", server.port()))
            .await
            .expect("connects");
        client
            .write_all(
                b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n\
                  Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
                  Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n",
            )
            .await
            .unwrap();
        let (head, _) = read_head(&mut client).await.unwrap().expect("an answer");
        assert!(
            String::from_utf8_lossy(&head).starts_with("HTTP/1.1 101"),
            "{}",
            String::from_utf8_lossy(&head)
        );
        client.write_all(&frame(true, 2, 16 << 20)).await.unwrap();
        // The connection ends (after a close frame 1009, and what the server had sent before).
        let mut received = Vec::new();
        let ended = tokio::time::timeout(std::time::Duration::from_secs(10), async {
            let mut buf = [0u8; 4096];
            loop {
                match client.read(&mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => received.extend_from_slice(&buf[..n]),
                }
            }
        })
        .await;
        assert!(ended.is_ok(), "the viewer is still connected");
        assert!(
            received.ends_with(&[0x88, 0x02, 0x03, 0xF1]),
            "a close frame, message too big"
        );
    }

    /// The area is made once a campaign; a viewer subscribed to it gets it again as each test
    /// starts and ends (the recorder repeats the latched messages with every `/tests` message),
    /// so one that lost it is not left without an area for the rest of the campaign.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_subscribed_viewer_gets_the_area_again_as_each_test_starts_and_ends() {
        use futures::{SinkExt, StreamExt};
        use tokio_tungstenite::tungstenite::Message;

        let (view, server) = LiveView::start(SocketAddr::from(([127, 0, 0, 1], 0)), &[], true)
            .await
            .expect("the live view starts");
        let scenario = scenarios::bundled::load("parking-lot-2anchors")
            .unwrap()
            .scenario;
        let origin = tokio::time::Instant::now();
        let mut recorder =
            crate::Recorder::live_only(origin, true, 1, &view, Some(&scenario)).unwrap();
        let mut socket = connect_viewer(server.port()).await;
        let within = std::time::Duration::from_secs(20);
        // Subscribes to the area as it is advertised.
        tokio::time::timeout(within, async {
            while let Some(Ok(message)) = socket.next().await {
                let Message::Text(text) = message else {
                    continue;
                };
                let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                let Some(channels) = json["channels"].as_array() else {
                    continue;
                };
                if let Some(area) = channels.iter().find(|c| c["topic"] == "/foxglove/area") {
                    let subscribe = serde_json::json!({
                        "op": "subscribe",
                        "subscriptions": [{"id": 7, "channelId": area["id"]}],
                    });
                    socket
                        .send(Message::Text(subscribe.to_string().into()))
                        .await
                        .unwrap();
                    return;
                }
            }
            panic!("the live view closed before advertising the area");
        })
        .await
        .expect("the area is advertised");
        // The next area that comes on the subscription.
        type Viewer =
            tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<TcpStream>>;
        async fn next_area(socket: &mut Viewer) -> serde_json::Value {
            while let Some(Ok(message)) = socket.next().await {
                if let Message::Binary(data) = message
                    && data.first() == Some(&1)
                {
                    assert_eq!(u32::from_le_bytes(data[1..5].try_into().unwrap()), 7);
                    return serde_json::from_slice(&data[13..]).unwrap();
                }
            }
            panic!("the live view closed");
        }
        // The area sent when the campaign began, as the viewer subscribes.
        let first = tokio::time::timeout(within, next_area(&mut socket))
            .await
            .expect("the area as the viewer subscribes");
        assert!(first["entities"].is_array(), "{first}");
        for event in [
            TestEventKind::Started { commands: 1 },
            TestEventKind::Ended {
                verdict: campaign::oracle::Verdict::Passed,
                reason: None,
            },
        ] {
            let said = format!("{event:?}");
            recorder
                .write(&crate::TestEvent {
                    test_index: 0,
                    event,
                })
                .unwrap();
            let again = tokio::time::timeout(within, next_area(&mut socket))
                .await
                .unwrap_or_else(|_| panic!("no area again after the test's {said}"));
            assert_eq!(again, first);
        }
    }

    /// Every channel is advertised as a viewer connects, before any test records: a channel
    /// made while a viewer is connected can be lost to it (see [`LiveView::start`]).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_viewer_that_connects_as_the_view_starts_is_advertised_every_channel() {
        use futures::StreamExt;
        use tokio_tungstenite::tungstenite::Message;

        let (_view, server) =
            LiveView::start(SocketAddr::from(([127, 0, 0, 1], 0)), &["a", "b-2"], false)
                .await
                .expect("the live view starts");
        let mut socket = connect_viewer(server.port()).await;
        // The campaign's own channels (the area's the one it sends on) and each car's.
        let mut expected: Vec<String> = [None, Some("a"), Some("b-2")]
            .iter()
            .flat_map(|car| {
                Topic::ALL
                    .into_iter()
                    .filter(|t| !t.is_simulator_only())
                    .map(move |t| match car {
                        Some(car) => format!("/{car}{}", t.name()),
                        None => t.name().to_owned(),
                    })
            })
            .collect();
        let mut advertised = Vec::new();
        // Until as many channels as expected are advertised (or 5 s pass: a missing one).
        let _ = tokio::time::timeout(std::time::Duration::from_secs(5), async {
            while let Some(Ok(message)) = socket.next().await {
                let Message::Text(text) = message else {
                    continue;
                };
                let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                if json["op"] == "advertise" {
                    for channel in json["channels"].as_array().unwrap() {
                        advertised.push(channel["topic"].as_str().unwrap().to_owned());
                    }
                }
                if advertised.len() >= expected.len() {
                    break;
                }
            }
        })
        .await;
        advertised.sort();
        expected.sort();
        assert_eq!(advertised, expected);
    }

    #[test]
    fn only_a_request_offering_the_specifications_name_alone_is_renamed() {
        let request =
            "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";
        let (renamed, yes) = offer_sdk_subprotocol(request);
        assert!(yes);
        assert_eq!(
            renamed,
            "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        );
        let both = "GET / HTTP/1.1\r\nsec-websocket-protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n\r\n";
        assert_eq!(offer_sdk_subprotocol(both), (both.to_owned(), false));
    }
}
