//! Links: a stray start byte holds back no frame and the byte timeout reports it; the framing on the pipe.

use std::time::Duration;

use car_link::frame::{FrameCodec, FrameEncoder, FrameError};
use car_link::transport::{Incoming, Link, PC_BYTE_TIMEOUT, sim_pipe};
use futures::{SinkExt, StreamExt};
use tokio::io::AsyncWriteExt;
use tokio_util::codec::Framed;

const GET_STATE_TO_1: [u8; 7] = [0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x03];

#[tokio::test(start_paused = true)]
async fn a_stray_start_byte_neither_delays_nor_loses_the_frame_after_it() {
    let mut pipe = sim_pipe();
    let mut link = Link::over_stream(pipe.host, PC_BYTE_TIMEOUT);
    // A stray long-form start announcing 1023 bytes, then a real frame, then silence.
    pipe.car
        .write_all(&[0x03, 0x03, 0xFF])
        .await
        .expect("written");
    pipe.car
        .write_all(&[0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x03])
        .await
        .expect("written");
    let started = tokio::time::Instant::now();
    // The real frame comes out at once (the second 0x03 announces too long a frame and is dropped first).
    let mut dropped = Vec::new();
    let payload = loop {
        match link.recv().await {
            Some(Incoming::Dropped(error)) => dropped.push(error),
            Some(Incoming::Payload(payload)) => break payload,
            other => panic!("expected the frame, got {other:?}"),
        }
    };
    assert_eq!(&payload[..], &[0x01, 0x78]);
    assert_eq!(started.elapsed(), Duration::ZERO);
    assert!(
        matches!(dropped[..], [FrameError::BadLength { offset: 1, .. }]),
        "{dropped:?}"
    );
    // The bogus candidate is reported when the byte timeout abandons it.
    match link.recv().await {
        Some(Incoming::Dropped(FrameError::Incomplete { offset: 0, .. })) => {}
        other => panic!("expected the abandoned candidate, got {other:?}"),
    }
    assert_eq!(started.elapsed(), PC_BYTE_TIMEOUT);
}

#[tokio::test(start_paused = true)]
async fn the_end_of_the_stream_closes_the_link() {
    let pipe = sim_pipe();
    let mut link = Link::over_stream(pipe.host, PC_BYTE_TIMEOUT);
    drop(pipe.car);
    assert!(matches!(link.recv().await, Some(Incoming::Closed(_))));
    assert!(link.recv().await.is_none());
}

#[tokio::test(start_paused = true)]
async fn the_car_end_speaks_the_same_framing() {
    let pipe = sim_pipe();
    let link = Link::over_stream(pipe.host, PC_BYTE_TIMEOUT);
    let mut car = Framed::new(pipe.car, FrameCodec::car());
    link.send(bytes::Bytes::from_static(&[0x01, 0x78]))
        .await
        .expect("sent");
    let frame = car
        .next()
        .await
        .expect("an item")
        .expect("no I/O error")
        .expect("a valid frame");
    assert_eq!(&frame.payload[..], &[0x01, 0x78]);
    assert_eq!(
        FrameEncoder::to_firmware()
            .encode_to_bytes(&frame.payload)
            .as_deref()
            .ok(),
        Some(&GET_STATE_TO_1[..])
    );
    // The car answers through the codec; the host link sees the payload.
    let mut link = link;
    car.send(bytes::Bytes::from_static(&[0x01, 0x3B]))
        .await
        .expect("sent");
    match tokio::time::timeout(Duration::from_secs(1), link.recv()).await {
        Ok(Some(Incoming::Payload(payload))) => assert_eq!(&payload[..], &[0x01, 0x3B]),
        other => panic!("expected the ack, got {other:?}"),
    }
}

#[tokio::test]
async fn the_codec_reports_garbage_and_keeps_decoding_until_the_end() {
    let mut bytes = vec![0x02, 0x09, 0xAA];
    bytes.extend_from_slice(&GET_STATE_TO_1);
    let reader = std::io::Cursor::new(bytes);
    let items: Vec<_> = tokio_util::codec::FramedRead::new(reader, FrameCodec::host())
        .collect()
        .await;
    let frames: Vec<_> = items
        .iter()
        .filter_map(|i| i.as_ref().ok()?.as_ref().ok())
        .collect();
    assert_eq!(frames.len(), 1);
    assert_eq!(&frames[0].payload[..], &[0x01, 0x78]);
    assert!(items.iter().all(|i| i.is_ok()), "no I/O errors: {items:?}");
}

/// A free UDP port on loopback (bound and let go).
async fn free_udp_port() -> u16 {
    let socket = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    socket.local_addr().expect("address").port()
}

/// The UDP link's socket is connected to the car (#51 item 12 a): a car that is not listening
/// yet (the system answers the first datagrams with *connection refused*) closes nothing, its
/// replies come through once it listens, and a spoofer's datagrams from another port of the
/// car's host never do.
#[tokio::test]
async fn a_udp_link_waits_for_a_car_not_listening_yet_and_hears_only_the_car() {
    let (car_port, reply_port) = (free_udp_port().await, free_udp_port().await);
    let mut link = Link::udp("127.0.0.1", car_port, reply_port)
        .await
        .expect("the link");
    // Nobody at the car's port: each datagram is refused (ICMP port unreachable).
    for _ in 0..3 {
        link.send(bytes::Bytes::from_static(b"early"))
            .await
            .expect("queued");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let car = tokio::net::UdpSocket::bind(("127.0.0.1", car_port))
        .await
        .expect("the car listens");
    let spoofer = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    spoofer
        .send_to(b"spoofed", ("127.0.0.1", reply_port))
        .await
        .expect("sent");
    link.send(bytes::Bytes::from_static(b"hello"))
        .await
        .expect("queued");
    let mut buf = [0u8; 64];
    let (n, from) = tokio::time::timeout(Duration::from_secs(5), car.recv_from(&mut buf))
        .await
        .expect("the car hears the link")
        .expect("received");
    assert_eq!(&buf[..n], b"hello");
    assert_eq!(from.port(), reply_port);
    spoofer
        .send_to(b"spoofed", ("127.0.0.1", reply_port))
        .await
        .expect("sent");
    car.send_to(b"reply", from).await.expect("sent");
    match tokio::time::timeout(Duration::from_secs(5), link.recv()).await {
        Ok(Some(Incoming::Payload(payload))) => assert_eq!(&payload[..], b"reply"),
        other => panic!("expected the car's reply, got {other:?}"),
    }
}
