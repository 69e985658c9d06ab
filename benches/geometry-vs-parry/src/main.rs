//! `cargo run --release`: the speed table (best of 5 rounds over 10,000 queries of each kind per
//! bundled area, 500 on the synthetic one; ns per query) and the exactness counts (disagreements between trajgen's exact
//! predicates and parry2d on near-degenerate points and segments), in Markdown.

use geometry_vs_parry::{
    near_edge_points, near_edge_segments, ns_per_query, on_boundary, queries, subjects,
};

const QUERIES: usize = 10_000;
/// On the synthetic area, where one trajgen query scans 40,000 edges.
const QUERIES_LARGE: usize = 500;

fn query_count(s: &geometry_vs_parry::Subject) -> usize {
    if s.vertices() > 1_000 {
        QUERIES_LARGE
    } else {
        QUERIES
    }
}
const ROUNDS: usize = 5;

fn main() {
    let subjects = subjects();

    println!(
        "## Speed (ns per query, best of {ROUNDS} rounds of {QUERIES} queries, {QUERIES_LARGE} on the synthetic area)\n"
    );
    println!(
        "| area | vertices | query | trajgen | parry2d-f64 | faster | parry2d-f64 `point_in_poly2d` |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|");
    for s in &subjects {
        let n = query_count(s);
        let q = queries(s, n, 1);
        let (area, parry) = (&s.area, &s.parry);
        let row = |query: &str, ours: f64, theirs: f64, extra: Option<f64>| {
            println!(
                "| {} | {} | {query} | {ours:.0} | {theirs:.0} | {} | {} |",
                s.name,
                s.vertices(),
                faster(ours, theirs),
                extra.map_or(String::new(), |x| format!("{x:.0}"))
            );
        };
        row(
            "contains (point)",
            ns_per_query(&q.points, ROUNDS, |&p| area.contains_point(p)),
            ns_per_query(&q.points, ROUNDS, |&p| parry.contains(p)),
            Some(ns_per_query(&q.points, ROUNDS, |&p| {
                parry.contains_linear(p)
            })),
        );
        row(
            "crosses (segment)",
            ns_per_query(&q.segments, ROUNDS, |&(a, b)| {
                area.segment_meets_boundary(a, b)
            }),
            ns_per_query(&q.segments, ROUNDS, |&(a, b)| parry.crosses(a, b)),
            None,
        );
        row(
            "clearance (segment)",
            ns_per_query(&q.segments, ROUNDS, |&(a, b)| {
                area.segment_boundary_distance_below(a, b, s.clearance)
                    .is_some()
            }),
            ns_per_query(&q.segments, ROUNDS, |&(a, b)| {
                parry.within(a, b, s.clearance)
            }),
            None,
        );
        row(
            "clip (ray)",
            ns_per_query(&q.rays, ROUNDS, |&(a, b)| area.clip_ray(a, b)),
            ns_per_query(&q.rays, ROUNDS, |&(a, b)| parry.clip(a, b)),
            None,
        );
        row(
            "distance (point)",
            ns_per_query(&q.points, ROUNDS, |&p| area.boundary_distance(p)),
            ns_per_query(&q.points, ROUNDS, |&p| parry.distance(p)),
            None,
        );
    }

    println!("\n## Agreement on the random queries\n");
    println!(
        "| area | contains ≠ | crosses ≠ | clearance ≠ | clip: hit ≠ | clip: max Δ (m) | distance: max Δ (m) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for s in &subjects {
        let n = query_count(s);
        let q = queries(s, n, 1);
        let (area, parry) = (&s.area, &s.parry);
        let contains = count(&q.points, |&p| area.contains_point(p) != parry.contains(p));
        let crosses = count(&q.segments, |&(a, b)| {
            area.segment_meets_boundary(a, b) != parry.crosses(a, b)
        });
        let clearance = count(&q.segments, |&(a, b)| {
            area.segment_boundary_distance_below(a, b, s.clearance)
                .is_some()
                != parry.within(a, b, s.clearance)
        });
        let clip_hit = count(&q.rays, |&(a, b)| {
            (area.clip_ray(a, b) != b) != (parry.clip(a, b) != b)
        });
        let clip_delta = q
            .rays
            .iter()
            .map(|&(a, b)| area.clip_ray(a, b).dist(parry.clip(a, b)))
            .fold(0.0, f64::max);
        let distance_delta = q
            .points
            .iter()
            .map(|&p| (area.boundary_distance(p) - parry.distance(p)).abs())
            .fold(0.0, f64::max);
        println!(
            "| {} | {contains} of {n} | {crosses} of {n} | {clearance} of {n} | {clip_hit} of {n} | {clip_delta:.1e} | {distance_delta:.1e} |",
            s.name
        );
    }

    println!(
        "\n## Exactness on near-degenerate cases (disagreements with trajgen's exact predicates)\n"
    );
    println!(
        "| area | points | on the boundary: parry says inside (BVH / `point_in_poly2d`) | off it: contains ≠ (BVH / `point_in_poly2d`) | segments | crosses ≠ (touching / 1e-9 m short / 1e-9 m past) |"
    );
    println!("|---|---:|---:|---:|---:|---:|");
    for s in &subjects {
        let (area, parry) = (&s.area, &s.parry);
        let points = near_edge_points(area, 2);
        let (on, off): (Vec<_>, Vec<_>) = points.iter().partition(|&&p| on_boundary(area, p));
        // trajgen: a boundary point is not inside (`contains_point` is strict).
        let on_bvh = count(&on, |&&p| parry.contains(p));
        let on_linear = count(&on, |&&p| parry.contains_linear(p));
        let off_bvh = count(&off, |&&p| area.contains_point(p) != parry.contains(p));
        let off_linear = count(&off, |&&p| {
            area.contains_point(p) != parry.contains_linear(p)
        });
        let segments = near_edge_segments(area, 3);
        let mut crosses = [0usize; 3];
        for (k, &(a, b)) in segments.iter().enumerate() {
            if area.segment_meets_boundary(a, b) != parry.crosses(a, b) {
                crosses[k % 3] += 1;
            }
        }
        println!(
            "| {} | {} ({} on) | {on_bvh} / {on_linear} of {} | {off_bvh} / {off_linear} of {} | {} | {} ({} / {} / {}) |",
            s.name,
            points.len(),
            on.len(),
            on.len(),
            off.len(),
            segments.len(),
            crosses.iter().sum::<usize>(),
            crosses[0],
            crosses[1],
            crosses[2],
        );
    }
}

/// Which is faster and by how much.
fn faster(trajgen_ns: f64, parry_ns: f64) -> String {
    if trajgen_ns <= parry_ns {
        format!("trajgen {:.1}×", parry_ns / trajgen_ns)
    } else {
        format!("parry {:.0}×", trajgen_ns / parry_ns)
    }
}

fn count<T>(items: &[T], f: impl Fn(&T) -> bool) -> usize {
    items.iter().filter(|x| f(x)).count()
}
