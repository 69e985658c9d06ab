//! The firmware built for the host, run in virtual time, answering the car protocol.
//!
//! The firmware trees come from the environment: `DRIVECHECK_FIRMWARE` (any tree), and
//! `DRIVECHECK_FIRMWARE_10` / `DRIVECHECK_FIRMWARE_12` (a tree of that generation, whose version
//! is then checked too), each the path of a tree's `Embedded/RC_Controller`. Without any, the
//! tests say `skipped: no firmware tree` and pass, except under `CI=true`, where they fail.

use std::path::{Path, PathBuf};

use car_link::fault;
use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{Anchor, Dialect, RcControl, RcMode};
use car_link::{CarState, FaultKind, FirmwareVersion, Probe, Reply, Request};
use sitl::protocol::{Imu, MotorCommand, MotorValues, SitlFrame};
use sitl::{Build, SitlProcess};

struct Tree {
    var: &'static str,
    path: PathBuf,
    major: Option<u8>,
}

fn trees() -> Vec<Tree> {
    let mut out = Vec::new();
    for (var, major) in [
        ("DRIVECHECK_FIRMWARE", None),
        ("DRIVECHECK_FIRMWARE_10", Some(10)),
        ("DRIVECHECK_FIRMWARE_12", Some(12)),
    ] {
        if let Some(p) = std::env::var_os(var).filter(|p| !p.is_empty()) {
            out.push(Tree {
                var,
                path: PathBuf::from(p),
                major,
            });
        }
    }
    if out.is_empty() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true and no firmware tree: set DRIVECHECK_FIRMWARE (or DRIVECHECK_FIRMWARE_10 / _12) to a tree's Embedded/RC_Controller"
        );
        println!("skipped: no firmware tree");
    }
    out
}

fn cache() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("sitl-cache")
}

fn built(tree: &Tree) -> Build {
    let b = sitl::build(&tree.path, &cache())
        .unwrap_or_else(|e| panic!("{} ({}): {e}", tree.var, tree.path.display()));
    if let Some(major) = tree.major {
        assert_eq!(b.version.0, major, "{} is not a {major}.x tree", tree.var);
    }
    b
}

const START_US: u64 = 1_500_000;

/// Starts the executable, standing level (from time 0: the firmware takes its first IMU sample
/// as the initial attitude, and no gravity at all gives it a NaN one), and runs it past the
/// firmware's start-up.
fn started(b: &Build) -> SitlProcess {
    let mut p = SitlProcess::start(&b.executable).expect("the executable starts");
    assert_eq!(p.firmware_version(), b.version);
    level(&mut p, 0.0);
    let out = p.advance_to(START_US).expect("start-up runs");
    assert!(
        out.iter()
            .any(|f| matches!(f, SitlFrame::Note { text, .. } if text == "init done")),
        "no `init done` by {START_US} µs: {out:?}"
    );
    p
}

/// Standing level, with a little sensor noise: a perfectly constant IMU makes the firmware's
/// Madgwick filter divide by zero.
fn level(p: &mut SitlProcess, yaw_rate_dps: f32) {
    p.set_imu(Imu {
        accel: [0.0, 0.0, 1.0],
        gyro: [0.0, 0.0, yaw_rate_dps],
        mag: [0.0; 3],
    })
    .unwrap();
    p.set_imu_noise(0.002, 0.05, 42).unwrap();
}

fn version(b: &Build) -> FirmwareVersion {
    FirmwareVersion::new(b.version.0, b.version.1)
}

fn request(p: &mut SitlProcess, b: &Build, r: &Request) {
    let payload = r.encode(255, Dialect::host(version(b))).expect("encodes");
    let frame = FrameEncoder::to_firmware()
        .encode_to_bytes(&payload)
        .expect("frames");
    p.send_car_bytes(&frame).expect("sent");
}

fn replies(b: &Build, out: &[SitlFrame]) -> Vec<(u64, Reply)> {
    let mut decoder = FrameDecoder::host();
    let mut replies = Vec::new();
    for f in out {
        if let SitlFrame::CarBytes { t_us, bytes } = f {
            decoder.push(bytes);
            while let Some(frame) = decoder.next_frame() {
                let frame = frame.expect("the firmware frames correctly");
                let (_, reply) =
                    Reply::decode(&frame.payload, version(b)).expect("a reply car-link decodes");
                replies.push((*t_us, reply));
            }
        }
    }
    replies
}

fn get_state(p: &mut SitlProcess, b: &Build) -> (u64, CarState) {
    request(p, b, &Request::GetState);
    let t = p.now_us() + 20_000;
    let out = p.advance_to(t).expect("runs");
    let mut states: Vec<_> = replies(b, &out)
        .into_iter()
        .filter_map(|(t, r)| {
            if let Reply::State(s) = r {
                Some((t, s))
            } else {
                None
            }
        })
        .collect();
    assert_eq!(states.len(), 1, "one state reply to one GET_STATE: {out:?}");
    states.remove(0)
}

fn listing(dir: &Path) -> Vec<(String, u64)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                e.metadata().map(|m| m.len()).unwrap_or(0),
            )
        })
        .collect();
    v.sort();
    v
}

/// A copy of a tree's files (top folder, `imu/`, `cc1120/`; not ChibiOS) to break on purpose.
fn copy_tree(tree: &Path, to: &Path) {
    for sub in ["", "imu", "imu/BMI160_driver", "cc1120"] {
        let (from, dest) = (tree.join(sub), to.join(sub));
        let Ok(entries) = std::fs::read_dir(&from) else {
            continue;
        };
        std::fs::create_dir_all(&dest).unwrap();
        for e in entries.flatten() {
            if e.path().is_file() {
                std::fs::copy(e.path(), dest.join(e.file_name())).unwrap();
            }
        }
    }
}

fn append(path: &Path, text: &str) {
    let mut s = std::fs::read_to_string(path).unwrap();
    s.push_str(text);
    std::fs::write(path, s).unwrap();
}

#[test]
fn build_errors_name_the_file_and_the_symbol() {
    for tree in trees() {
        let t = tempfile::tempdir().unwrap();
        let copy = t.path().join("tree");
        copy_tree(&tree.path, &copy);
        append(
            &copy.join("pos.c"),
            "\nvoid sitl_test_missing_symbol(void);\nvoid sitl_test_caller(void) { sitl_test_missing_symbol(); }\n",
        );
        match sitl::build(&copy, &t.path().join("cache")) {
            Err(sitl::BuildError::Undefined { symbol, file, .. }) => {
                assert_eq!(symbol, "sitl_test_missing_symbol", "{}", tree.var);
                assert_eq!(file.as_deref(), Some("pos.c"), "{}", tree.var);
            }
            other => panic!("{}: expected an undefined symbol, got {other:?}", tree.var),
        }
        append(&copy.join("commands.c"), "\n#error sitl test error\n");
        match sitl::build(&copy, &t.path().join("cache")) {
            Err(sitl::BuildError::Compile {
                file, first_error, ..
            }) => {
                assert_eq!(file, "commands.c", "{}", tree.var);
                assert!(
                    first_error.contains("sitl test error"),
                    "{}: {first_error}",
                    tree.var
                );
            }
            other => panic!("{}: expected a compile error, got {other:?}", tree.var),
        }
    }
}

#[test]
fn builds_once_then_from_the_cache() {
    for tree in trees() {
        let before = listing(&tree.path);
        let b = built(&tree);
        assert_eq!(
            listing(&tree.path),
            before,
            "{}: the build wrote into the tree",
            tree.var
        );
        for f in ["pos.c", "pos_uwb.c", "commands.c", "packet.c", "buffer.c"] {
            assert!(
                b.compiled.iter().any(|c| c == f),
                "{}: {f} not compiled: {:?}",
                tree.var,
                b.compiled
            );
        }
        for s in [
            "chMtxLock",
            "chThdCreateStatic",
            "chVTGetSystemTimeX",
            "comm_can_dw_range",
            "__wrap_buffer_append_float32",
        ] {
            assert!(
                b.stubbed.iter().any(|x| x == s),
                "{}: {s} not among the stubs: {:?}",
                tree.var,
                b.stubbed
            );
        }
        assert!(
            !b.stubbed.iter().any(|s| s == "pos_init" || s == "memcpy"),
            "{:?}",
            b.stubbed
        );
        assert_eq!(b.tree_hash.len(), 64);
        let again = built(&tree);
        assert!(
            again.cached,
            "{}: the second build did not come from the cache",
            tree.var
        );
        assert_eq!(again.executable, b.executable);
        assert_eq!(
            (&again.compiled, &again.stubbed, &again.tree_hash),
            (&b.compiled, &b.stubbed, &b.tree_hash)
        );
    }
}

#[test]
fn answers_get_state_in_virtual_time() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        let (t, s) = get_state(&mut p, &b);
        assert!(
            (START_US..START_US + 20_000).contains(&t),
            "answered at {t} µs"
        );
        assert_eq!(s.version, version(&b));
        // nothing moved the car: at the origin, standing
        assert_eq!((s.px, s.py, s.speed), (0.0, 0.0, 0.0), "{s:?}");
        assert_eq!(p.now_us(), START_US + 20_000);
        assert!(p.quit().expect("quits").success());
    }
}

#[test]
fn the_same_inputs_give_the_same_outputs() {
    for tree in trees() {
        let b = built(&tree);
        let run = || {
            let mut p = started(&b);
            p.set_imu_noise(0.002, 0.05, 7).unwrap();
            let mut all = Vec::new();
            for k in 0..20u64 {
                p.set_imu(Imu {
                    accel: [0.01 * (k % 3) as f32, -0.02, 0.98],
                    gyro: [0.1, -0.2, 3.0],
                    mag: [0.0; 3],
                })
                .unwrap();
                request(&mut p, &b, &Request::GetState);
                all.extend(p.advance_to(START_US + (k + 1) * 50_000).unwrap());
            }
            all
        };
        let (a, c) = (run(), run());
        assert!(
            a.iter()
                .filter(|f| matches!(f, SitlFrame::CarBytes { .. }))
                .count()
                >= 20
        );
        assert_eq!(a, c, "{}: two runs differ", tree.var);
    }
}

#[test]
fn gyro_turns_the_fused_yaw_while_driving() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        p.advance_to(p.now_us() + 500_000).unwrap();
        let (_, before) = get_state(&mut p, &b);
        // 10 °/s about z for 2 s, rolling at about 1.6 m/s (12.x holds the IMU yaw while the car
        // stands: `clamp_imu_yaw_stationary`)
        level(&mut p, 10.0);
        for k in 1..=200i32 {
            p.set_motor_values(MotorValues {
                rpm: 3000.0,
                tachometer: k * 20,
                tachometer_abs: k * 20,
                v_in: 12.0,
                current_motor: 1.0,
                duty_now: 0.1,
            })
            .unwrap();
            p.advance_to(p.now_us() + 10_000).unwrap();
        }
        let (_, after) = get_state(&mut p, &b);
        let turned = (after.yaw - before.yaw + 540.0).rem_euclid(360.0) - 180.0;
        assert!(
            turned.abs() > 15.0 && turned.abs() < 25.0,
            "{}: yaw {} -> {} ({turned}°)",
            tree.var,
            before.yaw,
            after.yaw
        );
        assert!(
            after.gyro[2].abs() > 0.1,
            "the state's gyro z: {:?}",
            after.gyro
        );
    }
}

#[test]
fn rc_control_drives_the_motor_and_the_servo() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        request(
            &mut p,
            &b,
            &Request::RcControl(RcControl {
                mode: RcMode::Current,
                throttle: 5.0,
                steering: 0.5,
            }),
        );
        let mut out = p.advance_to(p.now_us() + 20_000).unwrap();
        assert!(out.iter().any(|f| matches!(f, SitlFrame::Motor { command: MotorCommand::Current(c), .. } if (c - 5.0).abs() < 1e-3)), "{}: {out:?}", tree.var);
        // The servo ramps as the board's driver does (10.x: a full sweep in 0.6 s; 12.x at once).
        out.extend(p.advance_to(p.now_us() + 1_000_000).unwrap());
        let servo: Vec<f32> = out
            .iter()
            .filter_map(|f| {
                if let SitlFrame::Servo { pos, .. } = f {
                    Some(*pos)
                } else {
                    None
                }
            })
            .collect();
        assert!(
            servo.last().is_some_and(|s| (s - 0.5).abs() > 0.05),
            "{}: the servo stayed centred: {out:?}",
            tree.var
        );
        // Every step on the way goes the same way, each at most a 60th of the travel on 10.x.
        let steps: Vec<f32> = servo.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            steps.windows(2).all(|w| w[0].signum() == w[1].signum()),
            "{}: the servo went back and forth: {servo:?}",
            tree.var
        );
        if tree.var.ends_with("10") {
            assert!(
                servo.len() > 2 && steps.iter().all(|d| d.abs() <= 1.0 / 60.0 + 1e-6),
                "{}: no ramp: {servo:?}",
                tree.var
            );
        }
    }
}

#[test]
fn motor_values_move_the_odometry() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        // a tachometer that counts up: the firmware's dead reckoning moves the car
        for k in 1..=100i32 {
            p.set_motor_values(MotorValues {
                rpm: 3000.0,
                tachometer: k * 20,
                tachometer_abs: k * 20,
                v_in: 12.0,
                current_motor: 1.0,
                duty_now: 0.1,
            })
            .unwrap();
            p.advance_to(p.now_us() + 10_000).unwrap();
        }
        let (_, s) = get_state(&mut p, &b);
        assert!(
            s.px.hypot(s.py) > 0.1,
            "{}: the car did not move: {s:?}",
            tree.var
        );
        assert!(s.speed > 0.0, "{}: speed {}", tree.var, s.speed);
        assert!(
            (s.v_in - 12.0).abs() < 0.01,
            "{}: v_in {}",
            tree.var,
            s.v_in
        );
    }
}

#[test]
fn uwb_ranges_are_requested_and_answered_asynchronously() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        // two anchors: with one, the firmware's UWB thread never picks a next anchor to range to
        request(
            &mut p,
            &b,
            &Request::AddUwbAnchor(Anchor {
                id: 7,
                px: 10.0,
                py: 0.0,
                height: 1.0,
            }),
        );
        request(
            &mut p,
            &b,
            &Request::AddUwbAnchor(Anchor {
                id: 8,
                px: 0.0,
                py: 10.0,
                height: 1.0,
            }),
        );
        let mut requests = 0;
        for _ in 0..30 {
            let out = p.advance_to(p.now_us() + 100_000).unwrap();
            for f in &out {
                if let SitlFrame::UwbRequest { id, dest, .. } = f {
                    requests += 1;
                    // the car stands at the origin; anchor 7, 10 m east, answers 8 m, anchor 8
                    // the true 10 m: the UWB position has to move about 2 m east
                    let range = match dest {
                        7 => 8.0,
                        8 => 10.0,
                        other => panic!("a range request to anchor {other}"),
                    };
                    p.send_uwb_range(*id, *dest, range).unwrap();
                }
            }
        }
        assert!(
            requests >= 25,
            "{}: {requests} range requests in 3 s",
            tree.var
        );
        let (_, s) = get_state(&mut p, &b);
        assert!(
            s.px_uwb > 1.5 && s.px_uwb < 2.2,
            "{}: UWB x {} after {requests} answers",
            tree.var,
            s.px_uwb
        );
        assert!(s.py_uwb.abs() < 0.5, "{}: UWB y {}", tree.var, s.py_uwb);
    }
}

fn gga(lat_min: f64, lon_min: f64) -> String {
    // 57° N, 11° E plus minutes, RTK fixed (quality 4)
    let body = format!(
        "GPGGA,120000.00,57{lat_min:010.7},N,011{lon_min:010.7},E,4,12,0.8,30.0,M,0.0,M,1.0,0000"
    );
    let sum = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{sum:02X}")
}

#[test]
fn nmea_fixes_reach_the_gnss_position() {
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        // the first fix sets the local frame, the next is 10 m north of it (1852 m a minute)
        p.send_nmea(&gga(42.0, 58.0)).unwrap();
        p.advance_to(p.now_us() + 100_000).unwrap();
        p.send_nmea(&gga(42.0 + 10.0 / 1852.0, 58.0)).unwrap();
        p.advance_to(p.now_us() + 100_000).unwrap();
        let (_, s) = get_state(&mut p, &b);
        assert!(
            (s.py_gps - 10.0).abs() < 0.2 && s.px_gps.abs() < 0.2,
            "{}: GNSS ({}, {})",
            tree.var,
            s.px_gps,
            s.py_gps
        );
    }
}

#[test]
fn the_state_saturates_as_the_board_converts() {
    // The `px` probe sets the fused x packed into GET_STATE. On the board the float-to-int
    // conversion saturates and gives 0 for NaN; a plain x86 conversion gives INT_MIN for both.
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        let printf = |p: &mut SitlProcess, cmd: String| {
            request(p, &b, &Request::TerminalCmd(cmd));
            let out = p.advance_to(p.now_us() + 20_000).unwrap();
            replies(&b, &out)
                .into_iter()
                .filter_map(|(_, r)| {
                    if let Reply::Printf(t) = r {
                        Some(t)
                    } else {
                        None
                    }
                })
                .collect::<Vec<_>>()
        };
        printf(&mut p, fault::set_enabled_command(true));
        let added = printf(
            &mut p,
            fault::add_fault_command(&Probe::Px, FaultKind::SetTo, 1e9, 0, 0),
        );
        assert!(
            added
                .iter()
                .any(|l| fault::is_add_fault_reply(l, &Probe::Px)),
            "{}: {added:?}",
            tree.var
        );
        let (_, s) = get_state(&mut p, &b);
        assert_eq!(s.px, f64::from(i32::MAX) / 1e4, "{}", tree.var);
        printf(&mut p, fault::CLEAR_FAULTS_COMMAND.to_string());
        printf(&mut p, fault::set_enabled_command(true));
        printf(
            &mut p,
            fault::add_fault_command(&Probe::Px, FaultKind::SetTo, f32::NAN, 0, 0),
        );
        let (_, s) = get_state(&mut p, &b);
        assert_eq!(s.px, 0.0, "{}", tree.var);
    }
}

#[test]
fn the_pulse_per_second_sets_the_time_of_day() {
    // A board with UBLOX_USE_PPS keeps its time of day by the receiver's pulse, set to the whole
    // second after the last NMEA time stamp; without the pulse it stays unknown (−1), and the
    // firmware's GNSS latency compensation looks up its pose history at no time at all.
    for tree in trees() {
        let b = built(&tree);
        let mut p = started(&b);
        p.send_nmea(&gga(42.0, 58.0)).unwrap(); // stamped 12:00:00.00
        p.advance_to(p.now_us() + 100_000).unwrap();
        let (_, before) = get_state(&mut p, &b);
        assert_eq!(before.ms_today, -1, "{}: {before:?}", tree.var);
        p.pps().unwrap();
        p.advance_to(p.now_us() + 100_000).unwrap();
        let (_, after) = get_state(&mut p, &b);
        let second = 12 * 3_600_000 + 1_000;
        assert!(
            (second..second + 200).contains(&after.ms_today),
            "{}: time of day {} after the pulse",
            tree.var,
            after.ms_today
        );
    }
}
