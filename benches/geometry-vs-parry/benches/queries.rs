//! Criterion benchmarks of the area queries, trajgen against parry2d-f64, on every bundled area
//! and the synthetic 40,000-vertex one: `cargo bench` in this directory. Each iteration runs one
//! query of a fixed set of 1,000 (the reported time is per query).

use criterion::{Criterion, criterion_group, criterion_main};
use geometry_vs_parry::{queries, subjects};
use std::hint::black_box;

fn area_queries(c: &mut Criterion) {
    for s in subjects() {
        let q = queries(&s, 1_000, 1);
        let (area, parry) = (&s.area, &s.parry);
        let mut group = c.benchmark_group(format!("{} ({} vertices)", s.name, s.vertices()));
        let mut cycle = |name: &str, n: usize, mut f: Box<dyn FnMut(usize) + '_>| {
            let mut i = 0;
            group.bench_function(name, |b| {
                b.iter(|| {
                    i = (i + 1) % n;
                    f(i)
                })
            });
        };
        cycle(
            "contains/trajgen",
            q.points.len(),
            Box::new(|i| {
                black_box(area.contains_point(q.points[i]));
            }),
        );
        cycle(
            "contains/parry",
            q.points.len(),
            Box::new(|i| {
                black_box(parry.contains(q.points[i]));
            }),
        );
        cycle(
            "crosses/trajgen",
            q.segments.len(),
            Box::new(|i| {
                let (a, b) = q.segments[i];
                black_box(area.segment_meets_boundary(a, b));
            }),
        );
        cycle(
            "crosses/parry",
            q.segments.len(),
            Box::new(|i| {
                let (a, b) = q.segments[i];
                black_box(parry.crosses(a, b));
            }),
        );
        cycle(
            "clearance/trajgen",
            q.segments.len(),
            Box::new(|i| {
                let (a, b) = q.segments[i];
                black_box(area.segment_boundary_distance_below(a, b, s.clearance));
            }),
        );
        cycle(
            "clearance/parry",
            q.segments.len(),
            Box::new(|i| {
                let (a, b) = q.segments[i];
                black_box(parry.within(a, b, s.clearance));
            }),
        );
        cycle(
            "clip/trajgen",
            q.rays.len(),
            Box::new(|i| {
                let (a, b) = q.rays[i];
                black_box(area.clip_ray(a, b));
            }),
        );
        cycle(
            "clip/parry",
            q.rays.len(),
            Box::new(|i| {
                let (a, b) = q.rays[i];
                black_box(parry.clip(a, b));
            }),
        );
        cycle(
            "distance/trajgen",
            q.points.len(),
            Box::new(|i| {
                black_box(area.boundary_distance(q.points[i]));
            }),
        );
        cycle(
            "distance/parry",
            q.points.len(),
            Box::new(|i| {
                black_box(parry.distance(q.points[i]));
            }),
        );
        group.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = area_queries
}
criterion_main!(benches);
