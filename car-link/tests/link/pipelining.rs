//! The state stream keeps several GET_STATE requests in flight, so that over a link whose round trip is longer
//! than the polling period a sample still arrives every period. In virtual time, over an in-process pipe with a
//! fixed delay each way.

use crate::support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use car_link::client::{Car, CarError, LinkConfig, StatePolling, StateSample};
use car_link::message::Request;
use futures::StreamExt;
use support::{Behaviour, Log, serve, slow_pipe};
use tokio::time::Instant;

/// 150 ms each way: a 300 ms round trip, six times the polling period.
const ONE_WAY: Duration = Duration::from_millis(150);
const ROUND_TRIP: Duration = Duration::from_millis(300);
const PERIOD: Duration = Duration::from_millis(50);

/// A car behind the slow pipe; request timeout 1 s (the default 250 ms is shorter than the round trip).
async fn slow_car(behaviour: Behaviour) -> (Car, Arc<Mutex<Log>>) {
    let (host, car_end) = slow_pipe(ONE_WAY);
    let log = Arc::new(Mutex::new(Log::default()));
    tokio::spawn(serve(car_end, behaviour, log.clone()));
    let config = LinkConfig {
        request_timeout: Duration::from_secs(1),
        keepalive: None,
        ..LinkConfig::default()
    };
    let car = Car::over_stream(host, config).await.expect("handshake");
    (car, log)
}

fn state_requests(log: &Arc<Mutex<Log>>) -> usize {
    log.lock()
        .map(|l| {
            l.requests
                .iter()
                .filter(|r| matches!(r, Request::GetState))
                .count()
        })
        .unwrap_or_default()
}

fn largest_gap(samples: &[StateSample]) -> Duration {
    samples
        .windows(2)
        .map(|w| w[1].received_at.duration_since(w[0].received_at))
        .max()
        .unwrap_or_default()
}

#[tokio::test(start_paused = true)]
async fn a_sample_arrives_every_period_although_the_round_trip_is_six_periods() {
    let (car, log) = slow_car(Behaviour::default()).await;
    let before = state_requests(&log);
    let started = Instant::now();
    let samples: Vec<StateSample> = car
        .state_stream(PERIOD)
        .take(40)
        .map(|item| item.expect("a sample"))
        .collect()
        .await;
    // One in flight at a time, 40 samples would take 40 round trips (12 s) and come 300 ms apart.
    assert_eq!(largest_gap(&samples), PERIOD);
    assert_eq!(started.elapsed(), ROUND_TRIP + PERIOD * 39);
    // Each sample is stamped with its own request: the round trip stays the link's.
    assert!(samples.iter().all(|s| s.rtt() == ROUND_TRIP), "{samples:?}");
    assert!(
        samples
            .windows(2)
            .all(|w| w[1].requested_at - w[0].requested_at == PERIOD)
    );
    // Several requests in flight: six had left (at 0, 50, …, 250 ms) when the first reply came back.
    assert!(samples[5].requested_at < samples[0].received_at);
    let health = car.health();
    assert_eq!(health.rtt_p99, Some(ROUND_TRIP));
    assert_eq!(health.timeouts, 0);
    // The stream sent no more than it needed: the samples, plus those still in flight when it was dropped.
    let sent = state_requests(&log) - before;
    assert!((40..=40 + 7).contains(&sent), "{sent} requests");
}

#[tokio::test(start_paused = true)]
async fn at_most_the_cap_is_in_flight_and_the_rest_waits() {
    let (car, log) = slow_car(Behaviour::default()).await;
    let polling = StatePolling {
        period: PERIOD,
        timeout: Duration::from_secs(1),
        max_in_flight: 2,
    };
    let before = state_requests(&log);
    let stream = car.poll_states(polling);
    futures::pin_mut!(stream);
    let first = stream.next().await.expect("an item").expect("a sample");
    // Two requests left at once (t = 0 and 50 ms); the third waited for the first reply (at 300 ms).
    assert_eq!(first.rtt(), ROUND_TRIP);
    let second = stream.next().await.expect("an item").expect("a sample");
    assert_eq!(second.requested_at - first.requested_at, PERIOD);
    let third = stream.next().await.expect("an item").expect("a sample");
    assert_eq!(third.requested_at, first.received_at);
    assert!(state_requests(&log) - before <= 4);
}

#[tokio::test(start_paused = true)]
async fn a_lost_reply_neither_wedges_the_stream_nor_stamps_round_trips_beyond_the_timeout() {
    // Every 10th GET_STATE reply is lost (the handshake's is the first GET_STATE).
    let behaviour = Behaviour {
        lose_every_nth_state: Some(10),
        ..Behaviour::default()
    };
    let (car, _) = slow_car(behaviour).await;
    let timeout = ROUND_TRIP + 2 * PERIOD;
    let items: Vec<Result<StateSample, CarError>> = car
        .poll_states(StatePolling::new(PERIOD, timeout))
        .take(200)
        .collect()
        .await;
    let samples: Vec<StateSample> = items
        .iter()
        .filter_map(|i| i.as_ref().ok())
        .copied()
        .collect();
    let lost = items.len() - samples.len();
    // 20 replies were lost (one in ten of 200 requests); each is reported once its request's deadline passed,
    // except for at most one still shifted when the stream ended.
    assert!(
        items
            .iter()
            .filter_map(|i| i.as_ref().err())
            .all(|e| matches!(e, CarError::NoReply { tries: 1, .. })),
    );
    assert!((19..=20).contains(&lost), "{lost} errors");
    assert_eq!(car.health().timeouts, lost as u64);
    // A gap of two periods where a reply is missing, never more.
    assert_eq!(largest_gap(&samples), 2 * PERIOD);
    // The pairing is off by one request at most after a loss: round trips read long by a period, never
    // short, never beyond the timeout.
    assert!(
        samples
            .iter()
            .all(|s| (ROUND_TRIP..=ROUND_TRIP + PERIOD).contains(&s.rtt())),
        "{:?}",
        samples.iter().map(StateSample::rtt).collect::<Vec<_>>()
    );
}

#[tokio::test(start_paused = true)]
async fn a_single_read_is_answered_while_the_stream_runs() {
    let (car, _) = slow_car(Behaviour::default()).await;
    let stream = car.state_stream(PERIOD);
    futures::pin_mut!(stream);
    let _ = stream.next().await.expect("an item").expect("a sample");
    // A read from elsewhere joins the queue of requests in flight and gets a reply of its own.
    let (single, streamed) = tokio::join!(car.state(), stream.next());
    let single = single.expect("a state");
    assert!(streamed.expect("an item").is_ok());
    assert!(single.rtt() <= ROUND_TRIP + PERIOD, "{:?}", single.rtt());
    // Twenty more items: none is lost to the extra request.
    for _ in 0..20 {
        assert!(stream.next().await.expect("an item").is_ok());
    }
    assert_eq!(car.health().timeouts, 0);
}

#[tokio::test(start_paused = true)]
async fn a_lost_link_surfaces_as_errors_from_the_pipelined_stream() {
    let behaviour = Behaviour {
        hang_up_after: Some(12),
        ..Behaviour::default()
    };
    let (car, _) = slow_car(behaviour).await;
    let items: Vec<_> = car.state_stream(PERIOD).take(15).collect().await;
    let first_error = items.iter().position(Result::is_err).expect("an error");
    assert!(first_error >= 5, "{items:?}");
    assert!(
        items[first_error..]
            .iter()
            .all(|i| matches!(i, Err(CarError::LinkLost))),
        "{items:?}"
    );
}

#[test]
fn polling_keeps_enough_requests_in_flight_for_the_timeout() {
    let ms = Duration::from_millis;
    assert_eq!(StatePolling::new(ms(50), ms(1000)).max_in_flight, 20);
    assert_eq!(StatePolling::new(ms(50), ms(480)).max_in_flight, 10);
    assert_eq!(StatePolling::new(ms(50), ms(10)).max_in_flight, 1);
    assert_eq!(StatePolling::new(ms(50), Duration::ZERO).max_in_flight, 1);
    assert_eq!(StatePolling::new(ms(1), ms(10_000)).max_in_flight, 32);
    // A zero period would spin: it is raised to the minimum instead of panicking.
    let zero = StatePolling::new(Duration::ZERO, ms(5));
    assert_eq!(zero.period, car_link::client::MIN_STATE_PERIOD);
    assert_eq!(zero.max_in_flight, 5);
}
