//! Preflight, once per campaign: is this car fit for the method, and how fast is its link?
//!
//! Checks and settings, in order: the firmware generation (10.x or 12.x, the ones whose
//! behaviour the method knows); the main configuration (routes not repeated, speed mode, the
//! fused position reported: switched by a read-modify-write, then read back, and refused with a
//! clear message if it still deviates); the scenario's anchors uploaded; fault injection enabled
//! with every slot cleared; the car inside the fence; the UWB estimate reset to the RTK one; and
//! the round trip of GET_STATE measured over a few requests. The fault-injection and UWB
//! commands and the state samples are recorded in the campaign's journal.
//!
//! The round trip sets the limits the link needs: how long a state request may stay unanswered,
//! and whether the stale-telemetry limit must be raised. The telemetry keeps several GET_STATE
//! requests in flight (see `telemetry`), so on a long but steady link a sample still comes every
//! state period: what spaces samples further apart is the round trip's jitter and lost samples,
//! not the round trip itself.

use std::time::Duration;

use car_link::CarError;
use car_link::message::Anchor;
use scenarios::Scenario;
use trajgen::Point;

use super::journal::Journal;
use super::{RunConfig, RunError, retried};
use crate::vehicle::Vehicle;
use campaign::model::ProbeRates;
use car_link::firmware::MAX_STALE_LIMIT;
use recording::CarCommand;

/// GET_STATE requests the round trip is measured over.
const RTT_PROBES: usize = 20;
/// Round-trip probes sent per probe wanted, at most (a lossy link loses some).
const RTT_PROBE_TRIES: usize = 4;
/// Samples lost in a row (a request or its reply) that the stale-telemetry limit tolerates.
const LOST_IN_A_ROW: u32 = 2;

/// What preflight learned about the car and its link.
#[derive(Debug, Clone, PartialEq)]
pub struct Preflight {
    /// The configuration fields preflight switched off, with their old values (`ApRepeatRoutes
    /// (was 1)`); empty when the car was ready.
    pub switched_off: Vec<String>,
    /// The 99th-percentile GET_STATE round trip measured.
    pub rtt_p99: Duration,
    /// The median GET_STATE round trip measured.
    pub rtt_p50: Duration,
    /// How long one state request may take before the next tick asks again:
    /// `max(150 ms, rtt_p99 + 100 ms)` (a lost request is asked again soon, so that a few losses
    /// in a row stay within the stale-telemetry limit).
    pub sample_timeout: Duration,
    /// The stale-telemetry limit in force: the configured one, raised, if it is shorter, to what
    /// the link's jitter and losses need: `3 × state period + 2 × (rtt_p99 − rtt_p50)`, at most
    /// 1.9 s (see [`stale_limit`]).
    pub stale_after: Duration,
    /// The fault probes' call rates of this firmware with the scenario's anchors.
    pub rates: ProbeRates,
}

impl Preflight {
    /// Runs the preflight (see the module doc).
    ///
    /// Timeout: each command as bounded by the car's link configuration. Cancellation: the car
    /// may be left partly prepared; run the preflight again.
    pub async fn run<V: Vehicle>(
        car: &V,
        scenario: &Scenario,
        config: &RunConfig,
        journal: &Journal<'_>,
    ) -> Result<Self, RunError> {
        let version = car.version();
        if !version.profile().supported {
            return Err(RunError::Preflight(format!(
                "firmware {version}: the method knows 10.x and 12.x only"
            )));
        }
        let rates = ProbeRates::new(version, scenario.anchors.len());
        // The round trip first: every command after it waits what the link needs.
        let (rtt_p50, rtt_p99) = measure_round_trip(car, journal).await?;
        let per_try = per_try_timeout(rtt_p50, rtt_p99).map_err(RunError::Preflight)?;
        tracing::debug!(?rtt_p50, ?rtt_p99, ?per_try, "round trip measured");
        car.set_request_timeout(per_try);
        car.set_tries(tries_within(TRY_BUDGET, per_try).max(car.configured_tries()));
        let switched_off = prepare_configuration(car).await?;
        let anchors = anchors(scenario);
        retried(|| car.upload_anchors(&anchors))
            .await
            .map_err(|e| RunError::car("uploading the anchors", e))?;
        let enable = CarCommand::SetFaultInjection { enabled: true };
        retried(|| journal.call(None, enable.clone(), car.set_fi_enabled(true)))
            .await
            .map_err(|e| RunError::car("enabling fault injection", e))?;
        retried(|| journal.call(None, CarCommand::ClearFaults, car.clear_faults()))
            .await
            .map_err(|e| RunError::car("clearing the faults", e))?;
        check_inside_fence(car, scenario, journal).await?;
        retried(|| journal.call(None, CarCommand::ResetUwbPos, car.reset_uwb_pos()))
            .await
            .map_err(|e| RunError::car("resetting the UWB position", e))?;
        Ok(Self::from_round_trip(
            rtt_p50,
            rtt_p99,
            config,
            rates,
            switched_off,
        ))
    }

    fn from_round_trip(
        rtt_p50: Duration,
        rtt_p99: Duration,
        config: &RunConfig,
        rates: ProbeRates,
        switched_off: Vec<String>,
    ) -> Self {
        let sample_timeout = Duration::from_millis(150).max(rtt_p99 + Duration::from_millis(100));
        let stale_after = stale_limit(
            config.safety.stale_after,
            config.state_period,
            rtt_p50,
            rtt_p99,
        );
        Self {
            switched_off,
            rtt_p99,
            rtt_p50,
            sample_timeout,
            stale_after,
            rates,
        }
    }
}

/// The stale-telemetry limit in force: the configured one, raised if the link needs more, to
/// `(1 + 2) × state period + 2 × (rtt_p99 − rtt_p50)` at most 1.9 s (the car's watchdog brakes at
/// 2 s), but never lowered.
///
/// With GET_STATE pipelined, a sample comes every state period after a constant delay, so the
/// round trip itself does not space samples apart. Two things do: the jitter, which can move two
/// consecutive replies apart by up to the spread of the round trip (taken as `2 × (rtt_p99 −
/// rtt_p50)`: the median is not thrown off by one odd sample as the minimum is), and
/// lost requests or replies, each of which leaves out one sample; the limit tolerates
/// [`LOST_IN_A_ROW`] of them in a row. On the 4G-like link drivecheck is tested against (150 ms
/// + up to 40 ms each way, 2 % loss) this is about 230 ms, so the default 500 ms holds.
pub fn stale_limit(
    configured: Duration,
    state_period: Duration,
    rtt_p50: Duration,
    rtt_p99: Duration,
) -> Duration {
    let jitter = rtt_p99.saturating_sub(rtt_p50).saturating_mul(2);
    let needed = state_period
        .saturating_mul(1 + LOST_IN_A_ROW)
        .saturating_add(jitter)
        .min(MAX_STALE_LIMIT);
    configured.max(needed)
}

async fn prepare_configuration<V: Vehicle>(car: &V) -> Result<Vec<String>, RunError> {
    let changed = car.prepare_for_test_drive().await.map_err(|e| {
        RunError::Preflight(format!(
            "cannot switch off repeated routes (and time mode, UWB-reported position): {e}"
        ))
    })?;
    let config = car
        .main_config()
        .await
        .map_err(|e| RunError::car("reading the main configuration back", e))?;
    let left = config
        .test_drive_deviations()
        .map_err(|e| RunError::Preflight(e.to_string()))?;
    if !left.is_empty() {
        return Err(RunError::Preflight(format!(
            "the car keeps {left:?} after being told to switch them off: set repeat routes off \
             (and time mode, use_uwb_pos) in its configuration and try again"
        )));
    }
    Ok(changed
        .iter()
        .map(|(field, old)| format!("{field:?} (was {old})"))
        .collect())
}

fn anchors(scenario: &Scenario) -> Vec<Anchor> {
    scenario
        .anchors
        .iter()
        .map(|a| Anchor {
            id: i16::from(a.id),
            px: a.x as f32,
            py: a.y as f32,
            height: a.height as f32,
        })
        .collect()
}

async fn check_inside_fence<V: Vehicle>(
    car: &V,
    scenario: &Scenario,
    journal: &Journal<'_>,
) -> Result<(), RunError> {
    let sample = retried(|| car.state())
        .await
        .map_err(|e| RunError::car("reading the car's state", e))?;
    journal.state(&sample);
    let at = Point::new(sample.state.px, sample.state.py);
    if !at.is_finite() || !scenario.area.contains_point(at) {
        return Err(RunError::Preflight(format!(
            "the car is at ({:.2}, {:.2}), not inside the fence of {}: drive it into the area",
            at.x, at.y, scenario.name
        )));
    }
    Ok(())
}

/// The longest per-try timeout drivecheck gives a command: a link whose round trips need more is
/// refused (a lost packet would then cost seconds, and a car waits at most 2 s for a command
/// before its watchdog brakes it).
pub const MAX_PER_TRY: Duration = Duration::from_secs(4);
/// The shortest per-try timeout: the car answers within milliseconds, but a host under load
/// may not read its reply at once.
const MIN_PER_TRY: Duration = Duration::from_millis(250);

/// How long an acked command keeps being tried on a lossy link: as many tries as fit, at least
/// the configured number. At 30 % loss each way half the round trips fail; 10 tries of 250 ms
/// all failed about once in 800 packets, enough to abort one test in three, where 20 fail once
/// in a million.
const TRY_BUDGET: Duration = Duration::from_secs(5);

/// How many tries of `per_try` fit in `budget` (at least one).
fn tries_within(budget: Duration, per_try: Duration) -> u32 {
    let tries = budget.as_nanos() / per_try.as_nanos().max(1);
    u32::try_from(tries).unwrap_or(u32::MAX).max(1)
}

/// The per-try timeout of the car's commands for a link with these round trips:
/// `2 × p99 + 100 ms`, at least 250 ms. A try must outlast its round trip, or the late reply of a
/// try that gave up answers the next one (and an upload's read-back compares the wrong points);
/// it should not outlast it by much, or every lost packet costs that long (a 1 s per-try on a
/// loopback link made one upload take 10 s at 30 % loss). A link whose round trips need more than
/// [`MAX_PER_TRY`] is refused, saying what was measured and what it takes.
fn per_try_timeout(p50: Duration, p99: Duration) -> Result<Duration, String> {
    let needed = p99.saturating_mul(2) + Duration::from_millis(100);
    if needed <= MAX_PER_TRY {
        return Ok(needed.max(MIN_PER_TRY));
    }
    let limit = (MAX_PER_TRY - Duration::from_millis(100)) / 2;
    Err(format!(
        "the link is too slow: state requests took {} ms (median) and {} ms (p99) to be answered; \
         the car's commands would have to wait {} ms per try, and drivecheck waits at most {} ms \
         (a car brakes 2 s after its last command): drive over a link whose round trips stay \
         under {} ms",
        p50.as_millis(),
        p99.as_millis(),
        needed.as_millis(),
        MAX_PER_TRY.as_millis(),
        limit.as_millis()
    ))
}

/// The median and the 99th-percentile round trip of GET_STATE, one request at a time.
///
/// Replies to GET_STATE carry nothing that names their request: a reply is taken for the oldest
/// request still waiting, so the late reply of a request that gave up is taken for the next one,
/// which then reads a round trip far too short (on a link of 500 ms each way, 1 s tries measured
/// 0.4 s). So the keepalive is off while measuring (the probes feed the watchdog), after any
/// timeout since the link opened the measurement first waits until late replies have arrived, and
/// after a probe that got no answer the next is sent only after as long again. How long a probe
/// waits: three times the handshake's round trip when the handshake was answered at its first
/// try and nothing timed out since, else three times the first probe's; until a probe is
/// answered, the per-try timeout in force, doubled after every probe that got no answer, up to
/// [`MAX_PER_TRY`]. A lossy link loses some probes: up to [`RTT_PROBE_TRIES`] × [`RTT_PROBES`]
/// are sent to get [`RTT_PROBES`] answers; with fewer than half of them answered the link is
/// refused with its measured loss.
///
/// Bounded: a probe unanswered while a reply came from another car id is refused at once, naming
/// both ids; a car that answers none of [`SILENT_PROBES`] probes in a row is refused as one that
/// stopped answering; and the measurement ends after [`MEASURE_LIMIT`] with the round trips it
/// has (refused with fewer than half of [`RTT_PROBES`]). So it takes at most [`MEASURE_LIMIT`] +
/// one probe (2 × [`MAX_PER_TRY`]) + the first wait ([`MAX_PER_TRY`]): 72 s (`docs/car.md`,
/// *The dry run*).
async fn measure_round_trip<V: Vehicle>(
    car: &V,
    journal: &Journal<'_>,
) -> Result<(Duration, Duration), RunError> {
    car.set_keepalive(false);
    let measured = probe_round_trips(car, journal).await;
    car.set_keepalive(true);
    measured
}

/// Probes unanswered in a row after which the car is taken to have stopped answering: on a link
/// of a few milliseconds 20 probes of 250 ms and as long again after each, 10 s. A link that
/// loses half the round trips (30 % each way) loses 20 in a row about once in a million probes.
pub const SILENT_PROBES: usize = 20;
/// How long the round-trip measurement goes on collecting answers: it then goes on with those
/// it has.
pub const MEASURE_LIMIT: Duration = Duration::from_secs(60);

/// The wait of a probe on a link of round trip `rtt`: `3 × rtt + 100 ms`, within
/// [`MIN_PER_TRY`]..=[`MAX_PER_TRY`].
fn probe_wait(rtt: Duration) -> Duration {
    (rtt.saturating_mul(3) + Duration::from_millis(100)).clamp(MIN_PER_TRY, MAX_PER_TRY)
}

/// The probes of [`measure_round_trip`], with the keepalive off.
async fn probe_round_trips<V: Vehicle>(
    car: &V,
    journal: &Journal<'_>,
) -> Result<(Duration, Duration), RunError> {
    let began = tokio::time::Instant::now();
    let health = car.health();
    // The handshake's round trip is the link's when nothing timed out: no late reply can have
    // answered it.
    let known = if health.timeouts > 0 {
        tokio::time::sleep(MAX_PER_TRY).await;
        None
    } else {
        health.rtt_p99
    };
    let mut per_try = known.map_or_else(|| car.request_timeout().min(MAX_PER_TRY), probe_wait);
    let mut known = known.is_some();
    let mut rtts = Vec::with_capacity(RTT_PROBES);
    let mut sent = 0;
    let mut last_error = None;
    let mut unanswered = 0;
    let mut last_answer = tokio::time::Instant::now();
    while rtts.len() < RTT_PROBES
        && sent < RTT_PROBES * RTT_PROBE_TRIES
        && began.elapsed() < MEASURE_LIMIT
    {
        sent += 1;
        let others = car.health().other_car_replies;
        match car.state_within(per_try).await {
            Ok(sample) => {
                journal.state(&sample);
                if !known {
                    per_try = probe_wait(sample.rtt());
                    known = true;
                }
                rtts.push(sample.rtt());
                unanswered = 0;
                last_answer = tokio::time::Instant::now();
            }
            Err(CarError::LinkLost) => {
                return Err(RunError::car(
                    "measuring the round trip",
                    CarError::LinkLost,
                ));
            }
            Err(error) => {
                unanswered += 1;
                let health = car.health();
                if health.other_car_replies > others
                    && let Some(other) = health.last_other_car
                {
                    return Err(RunError::Preflight(format!(
                        "measuring the round trip: state request {sent} got no answer from car \
                         id {}, but {other}: another car on the link, or a bridge or proxy that \
                         changes the id",
                        other.expected
                    )));
                }
                if unanswered >= SILENT_PROBES {
                    let answered = match rtts.len() {
                        0 => "the handshake".to_owned(),
                        n => format!("{n} of {sent} state requests"),
                    };
                    return Err(RunError::Preflight(format!(
                        "measuring the round trip: the car answered {answered}, then none of \
                         {unanswered} state requests in {:.1} s: it stopped answering (last: \
                         {error})",
                        last_answer.elapsed().as_secs_f64()
                    )));
                }
                last_error = Some(error);
                tokio::time::sleep(per_try).await;
                if !known {
                    per_try = per_try.saturating_mul(2).min(MAX_PER_TRY);
                }
            }
        }
    }
    if rtts.len() < RTT_PROBES / 2 {
        let lost = sent - rtts.len();
        let error = last_error.map_or_else(String::new, |e| format!(" (last: {e})"));
        return Err(RunError::Preflight(format!(
            "measuring the round trip: {lost} of {sent} state requests in {:.1} s got no answer \
             ({:.0} % lost{error}); the link is too lossy to drive on",
            began.elapsed().as_secs_f64(),
            100.0 * lost as f64 / sent as f64
        )));
    }
    rtts.sort_unstable();
    let rank = (rtts.len() * 99).div_ceil(100).clamp(1, rtts.len());
    let median = (rtts.len() * 50).div_ceil(100).clamp(1, rtts.len());
    Ok((rtts[median - 1], rtts[rank - 1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    use campaign::model::Campaign;
    use car_link::frame::{FrameCodec, FrameEncoder};
    use futures::StreamExt;
    use tokio::io::AsyncWriteExt;

    fn scenario() -> Scenario {
        scenarios::bundled::load("parking-lot-2anchors")
            .unwrap()
            .scenario
    }

    fn one_test(dir: &std::path::Path) -> RunConfig {
        RunConfig::new(
            Campaign {
                seed: 7,
                tests: 1,
                no_faults: false,
            },
            dir.join("run"),
            "sim",
        )
    }

    /// The embedded simulated car behind a proxy that passes `kept` replies as they are and
    /// stamps every later one with car id `id`.
    fn renumbering_proxy(
        sim: tokio::io::DuplexStream,
        kept: usize,
        id: u8,
    ) -> tokio::io::DuplexStream {
        let (host, proxy) = tokio::io::duplex(1 << 16);
        let (sim_read, mut sim_write) = tokio::io::split(sim);
        let (mut proxy_read, mut proxy_write) = tokio::io::split(proxy);
        tokio::spawn(async move {
            let _ = tokio::io::copy(&mut proxy_read, &mut sim_write).await;
        });
        tokio::spawn(async move {
            let mut replies = tokio_util::codec::FramedRead::new(sim_read, FrameCodec::host());
            let mut passed = 0;
            while let Some(Ok(frame)) = replies.next().await {
                let Ok(frame) = frame else { continue };
                let mut payload = frame.payload.to_vec();
                if passed >= kept {
                    payload[0] = id;
                }
                passed += 1;
                let bytes = FrameEncoder::to_firmware()
                    .encode_to_bytes(&payload)
                    .unwrap();
                if proxy_write.write_all(&bytes).await.is_err() {
                    return;
                }
            }
        });
        host
    }

    /// A car that answers the handshake and then nothing: the dry run says so within seconds
    /// (it waited 630 s of 80 probes before).
    #[tokio::test(start_paused = true)]
    async fn a_car_that_stops_answering_after_the_handshake_is_given_up_within_seconds() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (car, sim) = crate::vehicle::connect_sim(&car_sim::SimConfig::from_scenario(&scenario))
            .await
            .unwrap();
        sim.freeze();
        let began = tokio::time::Instant::now();
        let error = crate::dry_run(&car, &scenario, &one_test(dir.path()), &crate::Silent)
            .await
            .expect_err("the car answers nothing");
        let took = began.elapsed();
        let text = error.to_string();
        assert!(
            text.starts_with(
                "preflight: measuring the round trip: the car answered the handshake, then none \
                 of 20 state requests in 9.8 s: it stopped answering (last: no reply to GetState"
            ),
            "{text}"
        );
        // The measurement's 10 s of silence and one probe, then the session's end (at most 3 s
        // to disarm a car that does not answer).
        assert!(
            took <= Duration::from_secs(11) + crate::session_end::DISARM_LIMIT,
            "{took:?}: {text}"
        );
    }

    /// A proxy that changes the car id of every reply after the handshake's: named at the first
    /// probe, with both ids.
    #[tokio::test(start_paused = true)]
    async fn a_reply_from_another_car_id_is_named_at_the_first_probe() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (stream, _sim) =
            car_sim::spawn_in_process(&car_sim::SimConfig::from_scenario(&scenario));
        let car = crate::vehicle::over_stream(renumbering_proxy(stream, 1, 9))
            .await
            .expect("the handshake's reply is the car's own");
        let began = tokio::time::Instant::now();
        let error = crate::dry_run(&car, &scenario, &one_test(dir.path()), &crate::Silent)
            .await
            .expect_err("the replies name another car");
        let took = began.elapsed();
        let text = error.to_string();
        assert!(
            text.contains(
                "state request 1 got no answer from car id 1, but a reply came from car id 9, \
                 expected 1: another car on the link, or a bridge or proxy that changes the id"
            ),
            "{text}"
        );
        assert!(
            took <= 2 * MAX_PER_TRY + crate::session_end::DISARM_LIMIT,
            "{took:?}: {text}"
        );
    }

    /// A link that loses 30 % each way (about half the round trips), 20-60 ms each way, is
    /// measured, not taken for a car that stopped answering, on every one of 30 seeds; and within
    /// the measurement's bound.
    #[tokio::test(start_paused = true)]
    async fn a_lossy_link_is_measured_and_not_given_up() {
        let scenario = scenario();
        for seed in 0..30 {
            let config = car_sim::SimConfig {
                seed,
                link: car_sim::LinkImpairment {
                    latency: ms(20),
                    jitter: ms(40),
                    loss: 0.3,
                    ..car_sim::LinkImpairment::default()
                },
                ..car_sim::SimConfig::from_scenario(&scenario)
            };
            let (car, _sim) = crate::vehicle::connect_sim(&config)
                .await
                .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            let journal = Journal::without_recording(None);
            let began = tokio::time::Instant::now();
            let (p50, p99) = measure_round_trip(&car, &journal)
                .await
                .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            assert!(
                ms(40) <= p50 && p50 <= p99 && p99 <= ms(130),
                "seed {seed}: {p50:?} {p99:?}"
            );
            assert!(
                began.elapsed() <= MEASURE_LIMIT,
                "seed {seed}: {:?}",
                began.elapsed()
            );
        }
    }

    const PERIOD: Duration = Duration::from_millis(50);
    const DEFAULT: Duration = campaign::safety::DEFAULT_STALE_AFTER;

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    #[test]
    fn the_per_try_timeout_follows_the_round_trip_and_a_link_too_slow_for_it_is_refused() {
        // A loopback link: the floor, not the 1 s a radio link needed.
        assert_eq!(per_try_timeout(ms(1), ms(3)), Ok(ms(250)));
        // 150 ms + up to 40 ms each way.
        assert_eq!(per_try_timeout(ms(340), ms(380)), Ok(ms(860)));
        // 500 ms each way: 1 s round trips get 2.16 s per try (the 1 s of before was answered
        // by the late replies of earlier tries).
        assert_eq!(per_try_timeout(ms(1010), ms(1030)), Ok(ms(2160)));
        let error = per_try_timeout(ms(1900), ms(2100)).unwrap_err();
        assert!(
            error.contains("1900 ms (median) and 2100 ms (p99)")
                && error.contains("4300 ms per try")
                && error.contains("under 1950 ms"),
            "{error}"
        );
    }

    #[test]
    fn a_faster_try_gets_more_tries_within_the_same_budget() {
        assert_eq!(tries_within(TRY_BUDGET, ms(250)), 20);
        assert_eq!(tries_within(TRY_BUDGET, ms(860)), 5);
        assert_eq!(tries_within(TRY_BUDGET, ms(6000)), 1);
    }

    #[test]
    fn a_long_steady_link_keeps_the_default_stale_limit() {
        // 150 ms + 0–40 ms each way: round trips of 300–380 ms, samples still every 50 ms.
        assert_eq!(stale_limit(DEFAULT, PERIOD, ms(340), ms(380)), DEFAULT);
        assert_eq!(stale_limit(DEFAULT, PERIOD, ms(2), ms(5)), DEFAULT);
    }

    #[test]
    fn jitter_raises_the_stale_limit_up_to_below_the_watchdog() {
        assert_eq!(stale_limit(DEFAULT, PERIOD, ms(250), ms(400)), DEFAULT);
        assert_eq!(stale_limit(DEFAULT, PERIOD, ms(250), ms(500)), ms(650));
        assert_eq!(
            stale_limit(DEFAULT, PERIOD, ms(100), ms(5000)),
            MAX_STALE_LIMIT
        );
        // A longer limit configured is kept.
        assert_eq!(stale_limit(ms(2500), PERIOD, ms(340), ms(380)), ms(2500));
    }
}
