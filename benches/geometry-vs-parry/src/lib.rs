//! trajgen's area queries and their parry2d counterparts, on the same areas and the same queries.
//!
//! The queries are the ones trajgen's generator and the safety checks call on their hot paths:
//! - `contains`: whether a point is strictly inside the drivable region (`Area::contains_point`);
//! - `crosses`: whether a segment meets the boundary (`Area::segment_meets_boundary`);
//! - `clearance`: whether a segment comes closer than the clearance to the boundary
//!   (`Area::segment_boundary_distance_below`);
//! - `clip`: where a ray first meets the boundary (`Area::clip_ray`);
//! - `distance`: a point's distance to the boundary (`Area::boundary_distance`).
//!
//! parry2d's counterparts use one `Polyline` (with its BVH) of every boundary edge for the
//! segment, ray and distance queries, and one closed `Polyline` per boundary loop (the fence
//! counter-clockwise, the cutouts clockwise, so the drivable side is always the left) for
//! containment, through `project_local_point_assuming_solid_interior_ccw` (BVH); the linear
//! crossing test `utils::point_in_poly2d` is measured too.

use parry2d_f64::math::{Pose, Vector};
use parry2d_f64::query::{self, PointQuery, Ray, RayCast};
use parry2d_f64::shape::{Polyline, Segment};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;
use trajgen::{Area, Point, Polygon, Strategy};

/// An area under test: trajgen's and parry2d's forms of it, and the generator's parameters.
pub struct Subject {
    /// Its name (a bundled scenario's, or `synthetic-40k`).
    pub name: String,
    /// trajgen's area.
    pub area: Area,
    /// parry2d's forms.
    pub parry: ParryArea,
    /// The clearance the generator keeps (m).
    pub clearance: f64,
    /// The length of the generator's rays (m).
    pub ray_length: f64,
    /// The segment lengths the generator places (m).
    pub segment: (f64, f64),
}

impl Subject {
    fn new(name: String, area: Area, config: trajgen::GeneratorConfig) -> Self {
        let parry = ParryArea::new(&area);
        Self {
            name,
            area,
            parry,
            clearance: config.constraints.clearance,
            ray_length: config.ray_length,
            segment: (
                config.constraints.min_segment,
                config.constraints.max_segment,
            ),
        }
    }

    /// Number of boundary vertices (fence and cutouts).
    pub fn vertices(&self) -> usize {
        self.area.edges().len()
    }
}

/// Every bundled area, then the synthetic 40,000-vertex one.
pub fn subjects() -> Vec<Subject> {
    let mut subjects: Vec<Subject> = scenarios::bundled::names()
        .iter()
        .map(|name| {
            let scenario = scenarios::bundled::load(name)
                .expect("bundled scenario")
                .scenario;
            let config = scenario.generator.generator_config(Strategy::Wedge);
            Subject::new((*name).to_owned(), scenario.area, config)
        })
        .collect();
    subjects.push(Subject::new(
        "synthetic-40k".to_owned(),
        synthetic_area(40_000),
        trajgen::GeneratorConfig::default(),
    ));
    subjects
}

/// A star-shaped fence of `vertices − 16` vertices around the origin (radius 100 m with waves of
/// a few metres, so it is concave everywhere) and four square cutouts of 4 vertices each.
pub fn synthetic_area(vertices: usize) -> Area {
    let n = vertices - 16;
    let fence = (0..n)
        .map(|i| {
            let theta = std::f64::consts::TAU * i as f64 / n as f64;
            let r = 100.0 + 3.0 * (37.0 * theta).sin() + 1.5 * (211.0 * theta).sin();
            Point::new(r * theta.cos(), r * theta.sin())
        })
        .collect();
    let square = |cx: f64, cy: f64| {
        Polygon::new(vec![
            Point::new(cx - 4.0, cy - 4.0),
            Point::new(cx + 4.0, cy - 4.0),
            Point::new(cx + 4.0, cy + 4.0),
            Point::new(cx - 4.0, cy + 4.0),
        ])
        .expect("square")
    };
    let cutouts = vec![
        square(40.0, 0.0),
        square(-40.0, 0.0),
        square(0.0, 40.0),
        square(0.0, -40.0),
    ];
    Area::new(Polygon::new(fence).expect("fence"), cutouts).expect("area")
}

/// parry2d's forms of an area.
pub struct ParryArea {
    /// Every boundary edge, in one polyline.
    pub edges: Polyline,
    /// One closed polyline per boundary loop, drivable side on the left: the fence
    /// counter-clockwise first, then the cutouts clockwise.
    pub loops: Vec<Polyline>,
    /// The same loops' vertices, for `point_in_poly2d`.
    pub rings: Vec<Vec<Vector>>,
}

fn v(p: Point) -> Vector {
    Vector::new(p.x, p.y)
}

fn closed(vertices: Vec<Vector>) -> Polyline {
    let n = vertices.len() as u32;
    let indices = (0..n).map(|i| [i, (i + 1) % n]).collect();
    Polyline::new(vertices, Some(indices))
}

impl ParryArea {
    fn new(area: &Area) -> Self {
        let vertices: Vec<Vector> = area.edges().iter().map(|e| v(e.a)).collect();
        // Edge k of trajgen's list goes from vertex k to the next vertex of its loop.
        let mut indices = Vec::with_capacity(vertices.len());
        let mut start = 0u32;
        for polygon in std::iter::once(area.fence()).chain(area.cutouts()) {
            let n = polygon.vertices().len() as u32;
            indices.extend((0..n).map(|i| [start + i, start + (i + 1) % n]));
            start += n;
        }
        let edges = Polyline::new(vertices, Some(indices));
        let oriented = |polygon: &Polygon, ccw: bool| {
            let mut ring: Vec<Vector> = polygon.vertices().iter().copied().map(v).collect();
            if (polygon.signed_area() > 0.0) != ccw {
                ring.reverse();
            }
            ring
        };
        let rings: Vec<Vec<Vector>> = std::iter::once(oriented(area.fence(), true))
            .chain(area.cutouts().iter().map(|c| oriented(c, false)))
            .collect();
        let loops = rings.iter().cloned().map(closed).collect();
        Self {
            edges,
            loops,
            rings,
        }
    }

    /// Inside the drivable region: on the left of every loop (BVH point projection).
    pub fn contains(&self, p: Point) -> bool {
        self.loops.iter().all(|l| {
            l.project_local_point_assuming_solid_interior_ccw(v(p))
                .0
                .is_inside
        })
    }

    /// Inside the drivable region by `point_in_poly2d` (linear crossing test per loop).
    pub fn contains_linear(&self, p: Point) -> bool {
        let (fence, cutouts) = self.rings.split_first().expect("a fence");
        parry2d_f64::utils::point_in_poly2d(v(p), fence)
            && !cutouts
                .iter()
                .any(|c| parry2d_f64::utils::point_in_poly2d(v(p), c))
    }

    /// Whether the segment `a–b` meets the boundary (a ray cast limited to the segment).
    pub fn crosses(&self, a: Point, b: Point) -> bool {
        self.edges
            .intersects_local_ray(&Ray::new(v(a), v(b - a)), 1.0)
    }

    /// Whether the segment `a–b` comes closer than `clearance` to the boundary.
    pub fn within(&self, a: Point, b: Point, clearance: f64) -> bool {
        self.segment_distance(a, b) < clearance
    }

    /// The distance from the segment `a–b` to the boundary.
    pub fn segment_distance(&self, a: Point, b: Point) -> f64 {
        let segment = Segment::new(v(a), v(b));
        query::distance(&Pose::IDENTITY, &segment, &Pose::IDENTITY, &self.edges)
            .expect("segment–polyline distance is supported")
            .distance
    }

    /// Where the ray `origin → end` first meets the boundary, or `end`.
    pub fn clip(&self, origin: Point, end: Point) -> Point {
        match self
            .edges
            .cast_local_ray(&Ray::new(v(origin), v(end - origin)), 1.0, false)
        {
            Some(t) => origin + (end - origin) * t,
            None => end,
        }
    }

    /// A point's distance to the boundary.
    pub fn distance(&self, p: Point) -> f64 {
        self.edges.distance_to_local_point(v(p), false)
    }
}

/// The queries one area is measured on, drawn from a fixed seed.
pub struct Queries {
    /// Points uniform in the fence's bounding box (inside and outside).
    pub points: Vec<Point>,
    /// Segments as the generator tries them: from a point inside, any heading, a length the
    /// constraints allow.
    pub segments: Vec<(Point, Point)>,
    /// Rays as the generator casts them: from a point inside, any heading, its ray length.
    pub rays: Vec<(Point, Point)>,
}

/// `n` queries of each kind on `subject`.
pub fn queries(subject: &Subject, n: usize, seed: u64) -> Queries {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let bbox = subject.area.bbox();
    let (w, h) = bbox.size();
    let in_box = |rng: &mut Pcg64Mcg| {
        Point::new(
            bbox.min.x + rng.random::<f64>() * w,
            bbox.min.y + rng.random::<f64>() * h,
        )
    };
    let points = (0..n).map(|_| in_box(&mut rng)).collect();
    let inside = |rng: &mut Pcg64Mcg| loop {
        let p = in_box(rng);
        if subject.area.contains_point(p) {
            return p;
        }
    };
    let (min, max) = subject.segment;
    let segments = (0..n)
        .map(|_| {
            let a = inside(&mut rng);
            let heading = rng.random::<f64>() * std::f64::consts::TAU;
            let length = min + rng.random::<f64>() * (max - min);
            (a, a + Point::from_heading(heading) * length)
        })
        .collect();
    let rays = (0..n)
        .map(|_| {
            let a = inside(&mut rng);
            let heading = rng.random::<f64>() * std::f64::consts::TAU;
            (a, a + Point::from_heading(heading) * subject.ray_length)
        })
        .collect();
    Queries {
        points,
        segments,
        rays,
    }
}

/// The boundary edges the near-degenerate cases are built on: every edge of a small area, about
/// 1,000 evenly spread ones of a large area.
fn sampled_edges(area: &Area) -> impl Iterator<Item = &trajgen::geometry::Edge> {
    area.edges()
        .iter()
        .step_by(area.edges().len().div_ceil(1_000))
}

/// Near-degenerate points: for every (sampled) boundary edge, its start vertex, its midpoint and a random
/// point of it as rounded to f64, and each of those moved off the edge's line along its normal by
/// ±1e-6, ±1e-9 and ±1e-12 m.
pub fn near_edge_points(area: &Area, seed: u64) -> Vec<Point> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut points = Vec::new();
    for e in sampled_edges(area) {
        let d = e.b - e.a;
        let normal = Point::new(-d.y, d.x) * (1.0 / d.norm());
        for t in [0.0, 0.5, rng.random::<f64>()] {
            let on = e.a + d * t;
            points.push(on);
            for offset in [1e-6, 1e-9, 1e-12] {
                points.push(on + normal * offset);
                points.push(on - normal * offset);
            }
        }
    }
    points
}

/// Near-degenerate segments: from a point inside the area, 1 m from a boundary point (a vertex,
/// a midpoint or a random point of a (sampled) edge), ending exactly at that point as rounded to f64, or
/// 1e-9 m short of it or past it.
pub fn near_edge_segments(area: &Area, seed: u64) -> Vec<(Point, Point)> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut segments = Vec::new();
    for e in sampled_edges(area) {
        let d = e.b - e.a;
        for t in [0.0, 0.5, rng.random::<f64>()] {
            let target = e.a + d * t;
            // A start 1 m away on the drivable side, in a random direction towards the edge.
            let Some(start) = (0..32).find_map(|_| {
                let heading = rng.random::<f64>() * std::f64::consts::TAU;
                let s = target + Point::from_heading(heading);
                area.contains_point(s).then_some(s)
            }) else {
                continue;
            };
            let dir = (target - start) * (1.0 / target.dist(start));
            segments.push((start, target));
            segments.push((start, target - dir * 1e-9));
            segments.push((start, target + dir * 1e-9));
        }
    }
    segments
}

/// Whether `p` lies on the boundary by trajgen's exact orientation (and within the edge's box).
pub fn on_boundary(area: &Area, p: Point) -> bool {
    area.edges()
        .iter()
        .any(|e| e.bbox.contains(p) && trajgen::geometry::orient(e.a, e.b, p) == 0.0)
}

/// Runs `f` on every item `rounds` times and returns the best round's nanoseconds per item.
pub fn ns_per_query<T, R>(items: &[T], rounds: usize, mut f: impl FnMut(&T) -> R) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..rounds {
        let started = std::time::Instant::now();
        for item in items {
            std::hint::black_box(f(std::hint::black_box(item)));
        }
        let ns = started.elapsed().as_nanos() as f64 / items.len() as f64;
        best = best.min(ns);
    }
    best
}
