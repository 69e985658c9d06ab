//! Figures for docs/sitl.md: build time of a tree (cold, then from the cache) and virtual seconds
//! per wall second, idle and with a GET_STATE every 50 ms.
//!
//! `cargo run --release -p sitl --example sitl_speed -- <tree> [virtual seconds]`

use std::path::PathBuf;
use std::time::Instant;

use sitl::SitlProcess;
use sitl::protocol::{Imu, SitlFrame};

fn crc16(data: &[u8]) -> u16 {
    let mut crc = 0u16;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// GET_STATE (command 120) to every car (255), framed by hand.
fn get_state_frame() -> Vec<u8> {
    let payload = [255u8, 120];
    let crc = crc16(&payload);
    vec![
        2,
        payload.len() as u8,
        payload[0],
        payload[1],
        (crc >> 8) as u8,
        crc as u8,
        3,
    ]
}

/// The process's CPU time (user + system) in seconds, from /proc (Linux), if readable.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // the fields after the command name in parentheses; utime and stime are the 12th and 13th
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn report(what: &str, seconds: u64, wall: f64, cpu: Option<f64>) {
    match cpu {
        Some(cpu) if cpu > 0.0 => println!(
            "{what}: {:.0} virtual s per wall s, {:.0} per CPU s of the executable",
            seconds as f64 / wall,
            seconds as f64 / cpu
        ),
        _ => println!("{what}: {:.0} virtual s per wall s", seconds as f64 / wall),
    }
}

fn start(exe: &std::path::Path) -> Result<SitlProcess, Box<dyn std::error::Error>> {
    let mut p = SitlProcess::start(exe)?;
    p.set_imu(Imu {
        accel: [0.0, 0.0, 1.0],
        gyro: [0.0; 3],
        mag: [0.0; 3],
    })?;
    p.set_imu_noise(0.002, 0.05, 1)?;
    p.advance_to(1_500_000)?;
    Ok(p)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tree = PathBuf::from(
        args.next()
            .ok_or("usage: sitl_speed <tree> [virtual seconds]")?,
    );
    let seconds: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(60);
    let cache = tempfile::tempdir()?;

    let t = Instant::now();
    let b = sitl::build(&tree, cache.path())?;
    let cold = t.elapsed();
    let t = Instant::now();
    let again = sitl::build(&tree, cache.path())?;
    let cached = t.elapsed();
    assert!(again.cached);
    println!(
        "firmware {}.{}: {} sources, {} shim symbols",
        b.version.0,
        b.version.1,
        b.compiled.len(),
        b.stubbed.len()
    );
    println!(
        "build: cold {:.2} s, cached {:.1} ms",
        cold.as_secs_f64(),
        cached.as_secs_f64() * 1e3
    );

    let span = seconds * 1_000_000;
    // idle, one ADVANCE
    let mut p = start(&b.executable)?;
    let (t0, c0) = (p.now_us(), cpu_seconds(p.id()));
    let t = Instant::now();
    p.advance_to(t0 + span)?;
    let wall = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds(p.id()).zip(c0).map(|(c1, c0)| c1 - c0);
    let (_, switches) = p.stats()?;
    report("idle, one advance", seconds, wall, cpu);
    println!("  ({switches} thread switches since start)");
    p.quit()?;

    // idle, lockstep in 10 ms steps
    let mut p = start(&b.executable)?;
    let (t0, c0) = (p.now_us(), cpu_seconds(p.id()));
    let t = Instant::now();
    for k in 1..=span / 10_000 {
        p.advance_to(t0 + k * 10_000)?;
    }
    let wall = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds(p.id()).zip(c0).map(|(c1, c0)| c1 - c0);
    report("idle, 10 ms steps", seconds, wall, cpu);
    p.quit()?;

    // a GET_STATE every 50 ms
    let mut p = start(&b.executable)?;
    let frame = get_state_frame();
    let (t0, c0) = (p.now_us(), cpu_seconds(p.id()));
    let t = Instant::now();
    let mut replies = 0usize;
    for k in 1..=span / 50_000 {
        p.send_car_bytes(&frame)?;
        let out = p.advance_to(t0 + k * 50_000)?;
        replies += out
            .iter()
            .filter(|f| matches!(f, SitlFrame::CarBytes { .. }))
            .count();
    }
    let wall = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds(p.id()).zip(c0).map(|(c1, c0)| c1 - c0);
    report("GET_STATE every 50 ms", seconds, wall, cpu);
    println!("  ({replies} replies to {} requests)", span / 50_000);
    p.quit()?;
    Ok(())
}
