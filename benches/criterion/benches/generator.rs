//! Criterion benchmarks of the trajectory generator on every bundled area: one extension of 4–7
//! points with the ahead margin (both strategies), and a 100 km area validation.
//!
//! `cargo bench -p drivecheck-benches --bench generator`. For percentiles (p50/p99/max) and failure
//! counts side by side, see `drivecheck-dev bench generator`.

use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use scenarios::bundled;
use trajgen::{Generator, RouteTail, Strategy, ValidationConfig, validate_area};

fn extension(c: &mut Criterion) {
    let mut group = c.benchmark_group("extension");
    for name in bundled::names() {
        let s = bundled::load(name).unwrap().scenario;
        for strategy in [Strategy::Wedge, Strategy::Reference] {
            let generator = Generator::new(s.generator.generator_config(strategy)).unwrap();
            let start = RouteTail::from_points(&s.start_route.positions()).unwrap();
            let mut rng = Pcg64Mcg::seed_from_u64(1);
            let mut tail = start;
            let mut count = 0usize;
            group.bench_function(format!("{name}/{strategy:?}"), |b| {
                b.iter(|| {
                    count += 1;
                    let n = 4 + count % 4;
                    match generator.extend(&s.area, &tail, n, &mut rng) {
                        Ok(extension) => tail = extension.next_tail,
                        Err(_) => tail = start,
                    }
                })
            });
        }
    }
    group.finish();
}

fn validation_100_km(c: &mut Criterion) {
    let mut group = c.benchmark_group("validate_100km");
    group.sample_size(10);
    for name in bundled::names() {
        let s = bundled::load(name).unwrap().scenario;
        let config = ValidationConfig::default()
            .with_km(100.0)
            .with_generator(s.generator.generator_config(Strategy::Wedge));
        let start = s.start_route.positions();
        let mut seed = 0;
        group.bench_function(*name, |b| {
            b.iter(|| {
                seed += 1;
                let mut rng = Pcg64Mcg::seed_from_u64(seed);
                validate_area(&s.area, &start, &config, &mut rng, &mut |_| {}).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, extension, validation_100_km);
criterion_main!(benches);
