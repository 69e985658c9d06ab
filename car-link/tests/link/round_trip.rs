//! GET_STATE round trip over loopback TCP against the minimal responder. A measurement, not a check: it is
//! ignored by default and prints its figures.
//!
//! `cargo test -p car-link --release --test link round_trip -- --ignored --nocapture`

use crate::support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use car_link::client::{Car, LinkConfig};
use car_link::health::percentile;
use support::{Behaviour, Log, serve};

const SAMPLES: usize = 5000;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a measurement; run it on purpose and read the figures"]
async fn get_state_round_trip_over_loopback_tcp() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let port = listener.local_addr().expect("address").port();
    tokio::spawn(async move {
        while let Ok((stream, _)) = listener.accept().await {
            let _ = stream.set_nodelay(true);
            tokio::spawn(serve(
                stream,
                Behaviour::default(),
                Arc::new(Mutex::new(Log::default())),
            ));
        }
    });
    let address = format!("tcp://127.0.0.1:{port}").parse().expect("address");
    let config = LinkConfig {
        keepalive: None,
        ..LinkConfig::default()
    };
    let car = Car::connect(&address, config).await.expect("connected");
    for _ in 0..200 {
        car.state().await.expect("warm-up state");
    }
    // Two views of each round trip: the caller's (around `state()`), and the link's (frame queued to reply
    // dispatched, what `LinkHealth` reports).
    let mut caller: Vec<Duration> = Vec::with_capacity(SAMPLES);
    let mut link: Vec<Duration> = Vec::with_capacity(SAMPLES);
    let started = std::time::Instant::now();
    for _ in 0..SAMPLES {
        let asked = std::time::Instant::now();
        let sample = car.state().await.expect("a state");
        caller.push(asked.elapsed());
        link.push(sample.rtt());
    }
    let elapsed = started.elapsed();
    for (view, rtts) in [("caller", &mut caller), ("link", &mut link)] {
        rtts.sort_unstable();
        println!(
            "GET_STATE over loopback TCP, {SAMPLES} sequential requests, {view} view: p50 {:?}, p99 {:?}, max {:?}",
            percentile(rtts, 50).unwrap_or_default(),
            percentile(rtts, 99).unwrap_or_default(),
            rtts.last().copied().unwrap_or_default(),
        );
    }
    println!("{:.0} states/s", SAMPLES as f64 / elapsed.as_secs_f64());
    let health = car.health();
    println!("client health: {health:?}");
    assert_eq!(health.timeouts, 0);
}
