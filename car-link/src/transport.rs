//! Links to a car: TCP to the bridge, UDP to the bridge, USB serial, or any byte stream (the in-process pipe to
//! the embedded simulator). A [`Link`] moves whole payloads; framing happens inside it (UDP carries one bare
//! payload per datagram).
//!
//! Each link runs a reader and a writer task on the current tokio runtime; dropping the [`Link`] stops both.

use std::io;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream};
use tokio::net::{TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::address::CarAddress;
use crate::frame::{FrameDecoder, FrameEncoder, FrameError};

/// The reference PC receivers reset their parser after this long without a byte.
pub const PC_BYTE_TIMEOUT: Duration = Duration::from_millis(500);
/// Buffer size of each direction of [`sim_pipe`].
pub const SIM_PIPE_BUFFER: usize = 64 * 1024;
/// Largest UDP datagram read.
const MAX_DATAGRAM: usize = 65_536;
/// Payloads queued for sending before `send` waits.
const SEND_QUEUE: usize = 64;

/// What a link delivers.
#[derive(Debug)]
pub enum Incoming {
    /// A payload with a valid frame (or a UDP datagram).
    Payload(Bytes),
    /// A candidate frame the decoder dropped (bad CRC, end byte or length, or abandoned after the byte timeout).
    Dropped(FrameError),
    /// The link is gone (end of stream, I/O error). Nothing follows.
    Closed(String),
}

/// The two ends of an in-process pipe: give `host` to [`crate::client::Car::over_stream`] and serve `car` with
/// [`crate::frame::FrameCodec::car`] (for example through `tokio_util::codec::Framed`).
#[derive(Debug)]
pub struct SimPipe {
    /// The end a client uses.
    pub host: DuplexStream,
    /// The end the simulated car serves.
    pub car: DuplexStream,
}

/// An in-process byte pipe with the same framing as TCP, for the embedded simulator. Works in virtual time.
///
/// The simulated car serves the `car` end with [`crate::frame::FrameCodec::car`], decodes [`Request`]s and
/// encodes [`Reply`]s in the firmware's dialect:
///
/// ```
/// use car_link::frame::FrameCodec;
/// use car_link::message::{CarState, Dialect, Reply, Request};
/// use car_link::transport::sim_pipe;
/// use car_link::{Car, LinkConfig, FirmwareVersion};
/// use futures::{SinkExt, StreamExt};
/// use tokio_util::codec::Framed;
///
/// # #[tokio::main(flavor = "current_thread")]
/// # async fn main() {
/// let pipe = sim_pipe();
/// tokio::spawn(async move {
///     let version = FirmwareVersion::V12_3;
///     let mut framed = Framed::new(pipe.car, FrameCodec::car());
///     while let Some(Ok(item)) = framed.next().await {
///         // Dropped candidates (bad CRC, …) are `Err` items: the firmware ignores them silently.
///         let Ok(frame) = item else { continue };
///         let Ok((_, Request::GetState)) = Request::decode(&frame.payload, version) else { continue };
///         let state = CarState { version, ms_today: 1_000, ..CarState::default() };
///         let Ok(payload) = Reply::State(state).encode(1, Dialect::firmware(version)) else { continue };
///         if framed.send(payload).await.is_err() {
///             break;
///         }
///     }
/// });
/// let car = Car::over_stream(pipe.host, LinkConfig::default()).await.expect("handshake");
/// assert_eq!(car.version(), FirmwareVersion::V12_3);
/// assert_eq!(car.state().await.expect("a state").ms_today(), 1_000);
/// # }
/// ```
///
/// [`Request`]: crate::message::Request
/// [`Reply`]: crate::message::Reply
pub fn sim_pipe() -> SimPipe {
    let (host, car) = tokio::io::duplex(SIM_PIPE_BUFFER);
    SimPipe { host, car }
}

/// An open link to a car.
#[derive(Debug)]
pub struct Link {
    outgoing: mpsc::Sender<Bytes>,
    incoming: mpsc::Receiver<Incoming>,
    tasks: Vec<JoinHandle<()>>,
    closed: bool,
}

impl Drop for Link {
    fn drop(&mut self) {
        for task in &self.tasks {
            task.abort();
        }
    }
}

/// The link is closed; the payload was not sent.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the link to the car is closed")]
pub struct LinkClosed;

impl Link {
    /// A link over any byte stream carrying frames: a TCP stream, a serial port, the host end of [`sim_pipe`].
    ///
    /// `byte_timeout` reports and frees a partly received frame candidate after that long without a
    /// byte ([`PC_BYTE_TIMEOUT`] in the reference tools); it never holds back the frames after it,
    /// which the decoder delivers as soon as their end byte arrives.
    pub fn over_stream<S>(stream: S, byte_timeout: Duration) -> Link
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let (reader, writer) = tokio::io::split(stream);
        let (out_tx, out_rx) = mpsc::channel(SEND_QUEUE);
        let (in_tx, in_rx) = mpsc::channel(SEND_QUEUE);
        let write_task = tokio::spawn(write_frames(writer, out_rx, in_tx.clone()));
        let read_task = tokio::spawn(read_frames(reader, in_tx, byte_timeout));
        Link {
            outgoing: out_tx,
            incoming: in_rx,
            tasks: vec![write_task, read_task],
            closed: false,
        }
    }

    /// Connects to the bridge over TCP.
    ///
    /// Timeout: gives up after `connect_timeout` with [`io::ErrorKind::TimedOut`]. Cancellation: dropping the
    /// future abandons the connection attempt.
    pub async fn tcp(host: &str, port: u16, connect_timeout: Duration) -> io::Result<Link> {
        let stream = tokio::time::timeout(connect_timeout, TcpStream::connect((host, port)))
            .await
            .map_err(|_| {
                io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("connecting to {host}:{port}"),
                )
            })??;
        stream.set_nodelay(true)?;
        Ok(Link::over_stream(stream, PC_BYTE_TIMEOUT))
    }

    /// Talks to the bridge over UDP: datagrams go to `host:port`, replies are received on local port
    /// `reply_port` (the bridge sends them from `port` to the sender's address at `port + 1`, so pass
    /// `port + 1` unless a test says otherwise).
    ///
    /// The reply port is bound on the local address that reaches the car (the loopback address for a
    /// car on loopback, else the address of the interface the system routes the car's address
    /// through), never on every interface, and the socket is connected to the car's address and
    /// port, so that the system itself drops every other datagram (checked again on receipt):
    /// anyone else's, another program's on the car's host included, never reaches the client. A
    /// car not listening yet (the system reports *connection refused* on a connected socket) is
    /// no error: its replies are waited for as before.
    ///
    /// Timeout: name resolution and binding are not timed. Cancellation: dropping the future is harmless.
    pub async fn udp(host: &str, port: u16, reply_port: u16) -> io::Result<Link> {
        let car = tokio::net::lookup_host((host, port))
            .await?
            .next()
            .ok_or_else(|| {
                io::Error::new(io::ErrorKind::NotFound, format!("no address for {host}"))
            })?;
        let local = SocketAddr::new(local_ip_towards(car).await?, reply_port);
        let socket = UdpSocket::bind(local).await?;
        socket.connect(car).await?;
        let socket = Arc::new(socket);
        let (out_tx, out_rx) = mpsc::channel(SEND_QUEUE);
        let (in_tx, in_rx) = mpsc::channel(SEND_QUEUE);
        let write_task = tokio::spawn(send_datagrams(socket.clone(), out_rx, in_tx.clone()));
        let read_task = tokio::spawn(receive_datagrams(socket, car, in_tx));
        Ok(Link {
            outgoing: out_tx,
            incoming: in_rx,
            tasks: vec![write_task, read_task],
            closed: false,
        })
    }

    /// Opens a USB serial port (CDC ACM; the baud rate is irrelevant, 115200 is used like the bridge).
    pub fn serial(path: &str) -> io::Result<Link> {
        use tokio_serial::SerialPortBuilderExt;
        let port = tokio_serial::new(path, 115_200)
            .open_native_async()
            .map_err(io::Error::from)?;
        Ok(Link::over_stream(port, PC_BYTE_TIMEOUT))
    }

    /// Opens the link an address names. `sim` cannot be opened here: the orchestrator owns the simulator and
    /// passes its pipe to [`Link::over_stream`].
    ///
    /// Timeout: a TCP connection attempt gives up after `connect_timeout`. Cancellation: dropping the future
    /// abandons the attempt.
    pub async fn open(address: &CarAddress, connect_timeout: Duration) -> io::Result<Link> {
        match address {
            CarAddress::Tcp { host, port } => Link::tcp(host, *port, connect_timeout).await,
            CarAddress::Udp { host, port } => Link::udp(host, *port, port.saturating_add(1)).await,
            CarAddress::Serial { path } => Link::serial(path),
            CarAddress::Sim => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "the address `sim` is resolved by the orchestrator: pass the simulator's pipe to Link::over_stream",
            )),
            CarAddress::Sitl { .. } => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "a `sitl:` address is resolved by the orchestrator: it builds and starts the firmware and passes its pipe to Link::over_stream",
            )),
        }
    }

    /// Queues a payload for sending.
    ///
    /// Timeout: none; it waits only while 64 payloads are already queued. Cancellation: dropping the future
    /// before it completes leaves the payload unsent.
    pub async fn send(&self, payload: Bytes) -> Result<(), LinkClosed> {
        self.outgoing.send(payload).await.map_err(|_| LinkClosed)
    }

    /// A sender that can be moved to other tasks.
    pub fn sender(&self) -> mpsc::Sender<Bytes> {
        self.outgoing.clone()
    }

    /// The next thing the link delivers; `None` after [`Incoming::Closed`] has been taken.
    ///
    /// Timeout: none, it waits for the car. Cancellation: safe, nothing is lost.
    pub async fn recv(&mut self) -> Option<Incoming> {
        if self.closed {
            return None;
        }
        let incoming = self.incoming.recv().await;
        self.closed = matches!(incoming, Some(Incoming::Closed(_)) | None);
        incoming
    }
}

async fn write_frames<W: AsyncWrite + Unpin>(
    mut writer: W,
    mut outgoing: mpsc::Receiver<Bytes>,
    incoming: mpsc::Sender<Incoming>,
) {
    let encoder = FrameEncoder::to_firmware();
    let mut buffer = BytesMut::new();
    while let Some(payload) = outgoing.recv().await {
        buffer.clear();
        if let Err(error) = encoder.encode(&payload, &mut buffer) {
            tracing::warn!(%error, "payload not sent");
            continue;
        }
        let written = async {
            writer.write_all(&buffer).await?;
            writer.flush().await
        };
        if let Err(error) = written.await {
            let _ = incoming
                .send(Incoming::Closed(format!("write failed: {error}")))
                .await;
            return;
        }
    }
}

async fn read_frames<R: AsyncRead + Unpin>(
    mut reader: R,
    incoming: mpsc::Sender<Incoming>,
    byte_timeout: Duration,
) {
    let mut decoder = FrameDecoder::host();
    let mut chunk = vec![0u8; 4096];
    loop {
        let read = if decoder.has_pending() {
            match tokio::time::timeout(byte_timeout, reader.read(&mut chunk)).await {
                Ok(read) => read,
                Err(_) => {
                    if deliver(&incoming, decoder.drain_stale()).await.is_err() {
                        return;
                    }
                    continue;
                }
            }
        } else {
            reader.read(&mut chunk).await
        };
        let reason = match read {
            Ok(0) => "end of stream".to_string(),
            Ok(n) => {
                decoder.push(&chunk[..n]);
                let items = std::iter::from_fn(|| decoder.next_frame()).collect();
                if deliver(&incoming, items).await.is_err() {
                    return;
                }
                continue;
            }
            Err(error) => format!("read failed: {error}"),
        };
        let _ = deliver(&incoming, decoder.drain_stale()).await;
        let _ = incoming.send(Incoming::Closed(reason)).await;
        return;
    }
}

async fn deliver(
    incoming: &mpsc::Sender<Incoming>,
    items: Vec<Result<crate::frame::Frame, FrameError>>,
) -> Result<(), LinkClosed> {
    for item in items {
        let message = match item {
            Ok(frame) => Incoming::Payload(frame.payload),
            Err(error) => Incoming::Dropped(error),
        };
        incoming.send(message).await.map_err(|_| LinkClosed)?;
    }
    Ok(())
}

/// The local address a datagram to `car` leaves from: loopback for a car on loopback, else the
/// address of the interface the system routes `car` through (asked by connecting an unbound UDP
/// socket, which sends nothing).
async fn local_ip_towards(car: SocketAddr) -> io::Result<IpAddr> {
    if car.ip().is_loopback() {
        return Ok(car.ip());
    }
    let any: SocketAddr = if car.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let probe = UdpSocket::bind(any).await?;
    probe.connect(car).await?;
    let ip = probe.local_addr()?.ip();
    if ip.is_unspecified() {
        return Err(io::Error::new(
            io::ErrorKind::AddrNotAvailable,
            format!("no local address routes to the car at {car}"),
        ));
    }
    Ok(ip)
}

async fn send_datagrams(
    socket: Arc<UdpSocket>,
    mut outgoing: mpsc::Receiver<Bytes>,
    incoming: mpsc::Sender<Incoming>,
) {
    while let Some(payload) = outgoing.recv().await {
        match socket.send(&payload).await {
            Ok(_) => continue,
            // An earlier datagram found no one at the car's port (ICMP port unreachable, reported
            // on the connected socket): the car may start listening later.
            Err(error) if error.kind() == io::ErrorKind::ConnectionRefused => {
                tracing::debug!(%error, "the car's port refused a datagram");
                continue;
            }
            Err(error) => {
                let _ = incoming
                    .send(Incoming::Closed(format!("UDP send failed: {error}")))
                    .await;
                return;
            }
        }
    }
}

async fn receive_datagrams(
    socket: Arc<UdpSocket>,
    car: SocketAddr,
    incoming: mpsc::Sender<Incoming>,
) {
    let mut datagram = vec![0u8; MAX_DATAGRAM];
    loop {
        match socket.recv_from(&mut datagram).await {
            Ok((n, from)) if from == car && n > 0 => {
                let payload = Bytes::copy_from_slice(&datagram[..n]);
                if incoming.send(Incoming::Payload(payload)).await.is_err() {
                    return;
                }
            }
            Ok((_, from)) => tracing::debug!(%from, "datagram from a stranger ignored"),
            // A datagram sent found no one at the car's port yet (see `Link::udp`).
            Err(error) if error.kind() == io::ErrorKind::ConnectionRefused => {
                tracing::debug!(%error, "the car's port refused a datagram");
            }
            Err(error) => {
                let _ = incoming
                    .send(Incoming::Closed(format!("UDP receive failed: {error}")))
                    .await;
                return;
            }
        }
    }
}
