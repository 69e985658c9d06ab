//! Simulated seconds per wall second for one car with all sensors (GNSS, two UWB anchors, the
//! autopilot driving a loop): the model stepped directly, and in-process through the protocol
//! shell on a paused tokio clock with a `car-link` client polling at 20 Hz.

use std::time::{Duration, Instant};

use car_link::message::RoutePoint as LinkPoint;
use car_link::{Car as LinkCar, LinkConfig};
use car_sim::{CarOptions, RoutePoint, SimCar, SimConfig, World, WorldAnchor, spawn_in_process};
use criterion::{Criterion, criterion_group, criterion_main};
use scenarios::geometry::Point;

fn world() -> World {
    World {
        anchors: vec![
            WorldAnchor {
                id: 50,
                position: Point::new(-10.0, -10.0),
                height: 1.0,
                range_bias_m: None,
            },
            WorldAnchor {
                id: 234,
                position: Point::new(10.0, 10.0),
                height: 1.0,
                range_bias_m: None,
            },
        ],
        ..World::default()
    }
}

fn circle(n: usize, speed: f64) -> Vec<(f64, f64, f64)> {
    (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            (5.0 * a.cos(), 5.0 * a.sin(), speed)
        })
        .collect()
}

/// One simulated minute of the model with a GET_STATE poll every 50 ms.
fn model_minute() -> SimCar {
    let mut car = SimCar::new(CarOptions {
        world: world(),
        preload_anchors: true,
        ..CarOptions::default()
    });
    let route: Vec<RoutePoint> = circle(30, 2.0)
        .iter()
        .map(|&(x, y, s)| RoutePoint::at(x as f32, y as f32, s as f32))
        .collect();
    car.add_points(&route);
    car.set_active(true, false);
    for _ in 0..6000 {
        car.step();
        if car.now_ms().is_multiple_of(50) {
            car.get_state();
        }
    }
    car
}

/// One simulated minute in-process, in virtual time, through the protocol and `car-link`.
fn in_process_minute(rt: &tokio::runtime::Runtime) {
    rt.block_on(async {
        let config = SimConfig {
            world: world(),
            preload_anchors: true,
            ..SimConfig::default()
        };
        let (stream, _sim) = spawn_in_process(&config);
        let car = LinkCar::over_stream(
            stream,
            LinkConfig {
                car_id: 1,
                ..LinkConfig::default()
            },
        )
        .await
        .expect("handshake");
        let route: Vec<LinkPoint> = circle(30, 2.0)
            .iter()
            .map(|&(x, y, s)| LinkPoint::at(x, y, s))
            .collect();
        for chunk in route.chunks(5) {
            car.add_points(chunk).await.expect("add");
        }
        car.set_autopilot(true, false).await.expect("active");
        let start = tokio::time::Instant::now();
        while start.elapsed() < Duration::from_secs(60) {
            tokio::time::sleep(Duration::from_millis(50)).await;
            car.state().await.expect("state");
        }
    });
}

fn report(name: &str, simulated_s: f64, mut run: impl FnMut()) {
    let start = Instant::now();
    run();
    let wall = start.elapsed().as_secs_f64();
    println!(
        "{name}: {:.0}× real time ({simulated_s} s simulated in {wall:.3} s)",
        simulated_s / wall
    );
}

fn bench(c: &mut Criterion) {
    report("model stepped directly", 60.0, || {
        model_minute();
    });
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("a runtime");
    report(
        "in-process, virtual time, car-link client at 20 Hz",
        60.0,
        || in_process_minute(&rt),
    );
    let mut group = c.benchmark_group("sim");
    group.sample_size(10);
    group.bench_function("model: 60 simulated s", |b| b.iter(model_minute));
    group.bench_function("in-process: 60 simulated s", |b| {
        b.iter(|| in_process_minute(&rt))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
