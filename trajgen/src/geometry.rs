//! Planar geometry of test areas: points (and waypoints, points with a speed), closed polygons and
//! the area (fence minus cutouts).
//!
//! Coordinates are local ENU metres (x east, y north); headings are radians counter-clockwise from
//! east. Polygons are stored open (the first vertex is not repeated) and always treated as closed:
//! every edge list includes the closing edge from the last vertex back to the first.
//!
//! Orientation tests use Shewchuk's adaptive exact predicate ([`robust::orient2d`]), so
//! intersection answers are exact for the given floating-point inputs. Touching counts as
//! intersecting: a segment that touches the fence is treated as leaving the area.

use std::ops::{Add, Mul, Neg, Sub};

use thiserror::Error;

/// A point (or a vector) in the local ENU plane, in metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
}

impl Point {
    /// A point from its coordinates.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// The unit vector at `heading` radians counter-clockwise from east.
    pub fn from_heading(heading: f64) -> Self {
        let (s, c) = heading.sin_cos();
        Self::new(c, s)
    }

    /// Euclidean length of the vector: the square root of its dot product with itself (a
    /// fraction of `hypot`'s cost, which only the planner's hot loops notice), or `hypot` where
    /// the squares overflow.
    pub fn norm(self) -> f64 {
        let n = self.dot(self).sqrt();
        if n.is_finite() {
            n
        } else {
            self.x.hypot(self.y)
        }
    }

    /// Distance to `other`.
    pub fn dist(self, other: Point) -> f64 {
        (other - self).norm()
    }

    /// Dot product.
    pub fn dot(self, other: Point) -> f64 {
        self.x * other.x + self.y * other.y
    }

    /// The z component of the cross product (positive when `other` is counter-clockwise of `self`).
    pub fn cross(self, other: Point) -> f64 {
        self.x * other.y - self.y * other.x
    }

    /// Heading of the vector, radians counter-clockwise from east, in (−π, π].
    pub fn heading(self) -> f64 {
        self.y.atan2(self.x)
    }

    /// The vector rotated counter-clockwise by `angle` radians.
    pub fn rotated(self, angle: f64) -> Self {
        let (s, c) = angle.sin_cos();
        Self::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }

    /// Whether both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

/// A point of a route with the speed the car drives towards it: the one shape of a route point
/// with a speed (scenario routes, segments, return routes, the route the car is streamed). File
/// formats and the car's wire protocol have their own spellings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// Position, local ENU metres.
    pub position: Point,
    /// Speed towards it, m/s.
    pub speed: f64,
}

impl Waypoint {
    /// A waypoint at `position` driven towards at `speed` m/s.
    pub const fn new(position: Point, speed: f64) -> Self {
        Self { position, speed }
    }
}

impl Add for Point {
    type Output = Point;
    fn add(self, rhs: Point) -> Point {
        Point::new(self.x + rhs.x, self.y + rhs.y)
    }
}

impl Sub for Point {
    type Output = Point;
    fn sub(self, rhs: Point) -> Point {
        Point::new(self.x - rhs.x, self.y - rhs.y)
    }
}

impl Mul<f64> for Point {
    type Output = Point;
    fn mul(self, k: f64) -> Point {
        Point::new(self.x * k, self.y * k)
    }
}

impl Neg for Point {
    type Output = Point;
    fn neg(self) -> Point {
        Point::new(-self.x, -self.y)
    }
}

impl From<[f64; 2]> for Point {
    fn from([x, y]: [f64; 2]) -> Self {
        Point::new(x, y)
    }
}

impl From<Point> for [f64; 2] {
    fn from(p: Point) -> Self {
        [p.x, p.y]
    }
}

/// The signed turn from heading `from` to heading `to`, normalised to (−π, π].
pub fn turn_angle(from: f64, to: f64) -> f64 {
    let mut d = (to - from) % std::f64::consts::TAU;
    if d > std::f64::consts::PI {
        d -= std::f64::consts::TAU;
    } else if d <= -std::f64::consts::PI {
        d += std::f64::consts::TAU;
    }
    d
}

/// Exact orientation of `c` relative to the directed line `a → b`: positive when counter-clockwise
/// (left), negative when clockwise (right), zero when collinear.
pub fn orient(a: Point, b: Point, c: Point) -> f64 {
    robust::orient2d(
        robust::Coord { x: a.x, y: a.y },
        robust::Coord { x: b.x, y: b.y },
        robust::Coord { x: c.x, y: c.y },
    )
}

/// Whether the closed segments `a–b` and `c–d` share at least one point (touching counts).
pub fn segments_intersect(a: Point, b: Point, c: Point, d: Point) -> bool {
    let o1 = orient(a, b, c);
    let o2 = orient(a, b, d);
    let o3 = orient(c, d, a);
    let o4 = orient(c, d, b);
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && on_segment(a, b, c))
        || (o2 == 0.0 && on_segment(a, b, d))
        || (o3 == 0.0 && on_segment(c, d, a))
        || (o4 == 0.0 && on_segment(c, d, b))
}

/// For a point `p` known to be collinear with `a–b`: whether it lies within the segment's extent.
fn on_segment(a: Point, b: Point, p: Point) -> bool {
    p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
}

/// The parameter `t ∈ [0, 1]` along `origin → end` of the first point the segment shares with
/// `c–d`, or `None` when they do not meet. Collinear overlaps give the nearest shared point.
pub fn segment_hit(origin: Point, end: Point, c: Point, d: Point) -> Option<f64> {
    if !segments_intersect(origin, end, c, d) {
        return None;
    }
    let r = end - origin;
    let s = d - c;
    let denom = r.cross(s);
    if denom != 0.0 {
        let t = (c - origin).cross(s) / denom;
        return Some(t.clamp(0.0, 1.0));
    }
    // Collinear overlap: the nearest of the overlap's ends along the ray.
    let len2 = r.dot(r);
    if len2 == 0.0 {
        return Some(0.0);
    }
    let tc = (c - origin).dot(r) / len2;
    let td = (d - origin).dot(r) / len2;
    let t = if (0.0..=1.0).contains(&tc.min(td)) || tc.min(td) > 1.0 {
        tc.min(td).max(0.0)
    } else {
        0.0
    };
    Some(t.clamp(0.0, 1.0))
}

/// Distance from `p` to the closed segment `a–b`.
pub fn point_segment_distance(p: Point, a: Point, b: Point) -> f64 {
    p.dist(closest_point_on_segment(p, a, b))
}

/// The point of the closed segment `a–b` nearest to `p` (`a` when the segment is a point).
pub fn closest_point_on_segment(p: Point, a: Point, b: Point) -> Point {
    let ab = b - a;
    let len2 = ab.dot(ab);
    if len2 == 0.0 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
}

/// Distance between the closed segments `a–b` and `c–d` (zero when they intersect).
pub fn segment_segment_distance(a: Point, b: Point, c: Point, d: Point) -> f64 {
    if segments_intersect(a, b, c, d) {
        return 0.0;
    }
    point_segment_distance(a, c, d)
        .min(point_segment_distance(b, c, d))
        .min(point_segment_distance(c, a, b))
        .min(point_segment_distance(d, a, b))
}

/// An axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BBox {
    /// Lower-left corner.
    pub min: Point,
    /// Upper-right corner.
    pub max: Point,
}

impl BBox {
    /// The box around a set of points; `None` when there are none.
    pub fn around(points: impl IntoIterator<Item = Point>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = it.next()?;
        Some(it.fold(
            BBox {
                min: first,
                max: first,
            },
            |b, p| b.including(p),
        ))
    }

    /// The smallest box holding this one and `p`.
    pub fn including(self, p: Point) -> Self {
        BBox {
            min: Point::new(self.min.x.min(p.x), self.min.y.min(p.y)),
            max: Point::new(self.max.x.max(p.x), self.max.y.max(p.y)),
        }
    }

    /// Whether the two boxes overlap (touching counts).
    pub fn overlaps(&self, other: &BBox) -> bool {
        self.min.x <= other.max.x
            && other.min.x <= self.max.x
            && self.min.y <= other.max.y
            && other.min.y <= self.max.y
    }

    /// Whether `p` lies in the box (boundary included).
    pub fn contains(&self, p: Point) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f64 {
        self.min.dist(self.max)
    }

    /// Width (x extent) and height (y extent).
    pub fn size(&self) -> (f64, f64) {
        (self.max.x - self.min.x, self.max.y - self.min.y)
    }
}

/// Why a list of vertices is not a simple polygon.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PolygonError {
    /// A polygon needs at least three vertices.
    #[error("a polygon needs at least 3 vertices, found {found}")]
    TooFewVertices {
        /// How many vertices there were.
        found: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("vertex {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the offending vertex.
        index: usize,
    },
    /// Two consecutive vertices coincide (including the closing pair).
    #[error("vertices {index} and {next} coincide")]
    RepeatedVertex {
        /// Index of the first vertex.
        index: usize,
        /// Index of the vertex that repeats it.
        next: usize,
    },
    /// Two edges that are not neighbours meet, or neighbours overlap.
    #[error("edge {first} (from vertex {first}) crosses edge {second} (from vertex {second})")]
    SelfIntersecting {
        /// Index of the first edge (edge i runs from vertex i to vertex i + 1, closing edge last).
        first: usize,
        /// Index of the second edge.
        second: usize,
    },
    /// All vertices lie on one line.
    #[error("the polygon has zero area")]
    Degenerate,
}

/// A simple closed polygon (stored open: the first vertex is not repeated).
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    vertices: Vec<Point>,
    bbox: BBox,
}

impl Polygon {
    /// A polygon from its vertices, checked to be simple: at least 3 finite vertices, no repeated
    /// consecutive vertices, no self-intersection, non-zero area.
    pub fn new(vertices: Vec<Point>) -> Result<Self, PolygonError> {
        if vertices.len() < 3 {
            return Err(PolygonError::TooFewVertices {
                found: vertices.len(),
            });
        }
        if let Some(index) = vertices.iter().position(|p| !p.is_finite()) {
            return Err(PolygonError::NonFinite { index });
        }
        let n = vertices.len();
        if let Some(index) = (0..n).find(|&i| vertices[i] == vertices[(i + 1) % n]) {
            return Err(PolygonError::RepeatedVertex {
                index,
                next: (index + 1) % n,
            });
        }
        if let Some((first, second)) = first_self_intersection(&vertices) {
            return Err(PolygonError::SelfIntersecting { first, second });
        }
        let bbox = BBox::around(vertices.iter().copied()).ok_or(PolygonError::Degenerate)?;
        let polygon = Self { vertices, bbox };
        if polygon.signed_area() == 0.0 {
            return Err(PolygonError::Degenerate);
        }
        Ok(polygon)
    }

    /// The vertices, open (the first is not repeated).
    pub fn vertices(&self) -> &[Point] {
        &self.vertices
    }

    /// The bounding box.
    pub fn bbox(&self) -> BBox {
        self.bbox
    }

    /// The edges, closing edge included: edge `i` runs from vertex `i` to vertex `i + 1`.
    pub fn edges(&self) -> impl Iterator<Item = (Point, Point)> + '_ {
        closed_edges(&self.vertices)
    }

    /// Signed area by the shoelace formula (positive for counter-clockwise vertex order).
    pub fn signed_area(&self) -> f64 {
        self.edges().map(|(a, b)| a.cross(b)).sum::<f64>() / 2.0
    }

    /// Area in square metres.
    pub fn area(&self) -> f64 {
        self.signed_area().abs()
    }

    /// Whether `p` lies strictly inside or on the boundary (crossing-number test with exact
    /// orientation; boundary points count as inside).
    pub fn contains(&self, p: Point) -> bool {
        if !self.bbox.contains(p) {
            return false;
        }
        let mut inside = false;
        for (a, b) in self.edges() {
            // An edge wholly above or below p neither crosses the horizontal line through p
            // nor holds p: no orientation needed (most edges, and the robust predicate is
            // what this test costs).
            if (p.y < a.y && p.y < b.y) || (p.y > a.y && p.y > b.y) {
                continue;
            }
            let o = orient(a, b, p);
            if o == 0.0 && on_segment(a, b, p) {
                return true;
            }
            if (a.y > p.y) != (b.y > p.y) {
                // The edge straddles the horizontal line through p: count it when p is left of the
                // upward edge (or right of the downward one), i.e. the crossing is to the right of p.
                let upward = b.y > a.y;
                if (o > 0.0) == upward {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Distance from `p` to the polygon's boundary.
    pub fn boundary_distance(&self, p: Point) -> f64 {
        self.edges()
            .map(|(a, b)| point_segment_distance(p, a, b))
            .fold(f64::INFINITY, f64::min)
    }
}

/// The closed edge list of an open vertex list.
fn closed_edges(vertices: &[Point]) -> impl Iterator<Item = (Point, Point)> + '_ {
    let n = vertices.len();
    (0..n).map(move |i| (vertices[i], vertices[(i + 1) % n]))
}

/// The first pair of edges `(i, j)`, `i < j`, that make the closed polyline non-simple: edges that
/// are not neighbours and meet, or neighbours that overlap beyond their shared vertex.
///
/// Near-linear for the polygons of real areas: edges are put in the cells of a uniform grid their
/// bounding boxes cover (about one cell per edge), and only edges sharing a cell are compared
/// (edges that meet share a cell). Small polygons compare every pair.
pub fn first_self_intersection(vertices: &[Point]) -> Option<(usize, usize)> {
    let n = vertices.len();
    let edges: Vec<(Point, Point)> = closed_edges(vertices).collect();
    let bad = |i: usize, j: usize| {
        let (a, b) = edges[i];
        let (c, d) = edges[j];
        if j == i + 1 || (i == 0 && j == n - 1) {
            // Neighbours share one vertex; they are bad only when they fold back on each other.
            let (shared, p, q) = if j == i + 1 { (b, a, d) } else { (a, b, c) };
            orient(p, shared, q) == 0.0 && (p - shared).dot(q - shared) > 0.0
        } else {
            segments_intersect(a, b, c, d)
        }
    };
    let grid = (n >= GRID_FROM_EDGES)
        .then(|| EdgeGrid::new(&edges))
        .flatten();
    let Some(grid) = grid else {
        return (0..n).find_map(|i| ((i + 1)..n).find(|&j| bad(i, j)).map(|j| (i, j)));
    };
    // For each edge, its later neighbours in the grid, in order: the first bad pair found is the
    // first in (i, j) order.
    let mut seen = vec![usize::MAX; n];
    let mut candidates = Vec::new();
    for (i, &edge) in edges.iter().enumerate() {
        candidates.clear();
        for cell in grid.cells_of(edge) {
            for &j in &grid.cells[cell] {
                if j > i && seen[j] != i {
                    seen[j] = i;
                    candidates.push(j);
                }
            }
        }
        candidates.sort_unstable();
        if let Some(&j) = candidates.iter().find(|&&j| bad(i, j)) {
            return Some((i, j));
        }
    }
    None
}

/// Polygons with this many edges or more are checked through an [`EdgeGrid`].
const GRID_FROM_EDGES: usize = 64;

/// A uniform grid over a polyline's bounding box with the edges whose bounding boxes cover each
/// cell.
struct EdgeGrid {
    origin: Point,
    cell: f64,
    columns: usize,
    rows: usize,
    cells: Vec<Vec<usize>>,
}

impl EdgeGrid {
    /// About one cell per edge; `None` for a degenerate or non-finite extent (the caller then
    /// compares every pair).
    fn new(edges: &[(Point, Point)]) -> Option<Self> {
        let bbox = BBox::around(edges.iter().map(|e| e.0))?;
        let extent = (bbox.max.x - bbox.min.x).max(bbox.max.y - bbox.min.y);
        if !extent.is_finite() || extent <= 0.0 {
            return None;
        }
        let per_side = (edges.len() as f64).sqrt().ceil().max(1.0);
        let cell = extent / per_side;
        let count = |span: f64| ((span / cell).floor() as usize).saturating_add(1);
        let columns = count(bbox.max.x - bbox.min.x);
        let rows = count(bbox.max.y - bbox.min.y);
        let mut grid = Self {
            origin: bbox.min,
            cell,
            columns,
            rows,
            cells: vec![Vec::new(); columns.checked_mul(rows)?],
        };
        for (k, &edge) in edges.iter().enumerate() {
            for c in grid.cells_of(edge).collect::<Vec<_>>() {
                grid.cells[c].push(k);
            }
        }
        Some(grid)
    }

    /// The cells the bounding box of `edge` covers.
    fn cells_of(&self, (a, b): (Point, Point)) -> impl Iterator<Item = usize> + '_ {
        let index = |v: f64, origin: f64, last: usize| {
            (((v - origin) / self.cell).floor().max(0.0) as usize).min(last)
        };
        let (x0, x1) = (
            index(a.x.min(b.x), self.origin.x, self.columns - 1),
            index(a.x.max(b.x), self.origin.x, self.columns - 1),
        );
        let (y0, y1) = (
            index(a.y.min(b.y), self.origin.y, self.rows - 1),
            index(a.y.max(b.y), self.origin.y, self.rows - 1),
        );
        (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| y * self.columns + x))
    }
}

/// Why a fence and its cutouts do not form a valid area.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AreaError {
    /// A cutout is not entirely inside the fence.
    #[error("cutout {index} is not entirely inside the fence")]
    CutoutOutsideFence {
        /// Index of the cutout.
        index: usize,
    },
    /// Two cutouts overlap or touch.
    #[error("cutouts {first} and {second} overlap")]
    CutoutsOverlap {
        /// Index of the first cutout.
        first: usize,
        /// Index of the second cutout.
        second: usize,
    },
}

/// A test area: the drivable region inside the fence and outside every cutout.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    fence: Polygon,
    cutouts: Vec<Polygon>,
    /// Every boundary edge (fence and cutouts, closing edges included) with its bounding box.
    edges: Vec<Edge>,
}

/// One boundary edge with its bounding box, for the fast rejection path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Start vertex.
    pub a: Point,
    /// End vertex.
    pub b: Point,
    /// Bounding box of the edge.
    pub bbox: BBox,
}

impl Area {
    /// An area from a fence and cutouts, checked: every cutout strictly inside the fence, no two
    /// cutouts overlapping or touching.
    pub fn new(fence: Polygon, cutouts: Vec<Polygon>) -> Result<Self, AreaError> {
        for (index, cutout) in cutouts.iter().enumerate() {
            let inside = cutout.vertices().iter().all(|&p| fence.contains(p))
                && !polygons_touch(&fence, cutout);
            if !inside {
                return Err(AreaError::CutoutOutsideFence { index });
            }
        }
        for first in 0..cutouts.len() {
            for second in (first + 1)..cutouts.len() {
                let (p, q) = (&cutouts[first], &cutouts[second]);
                if polygons_touch(p, q)
                    || q.contains(p.vertices()[0])
                    || p.contains(q.vertices()[0])
                {
                    return Err(AreaError::CutoutsOverlap { first, second });
                }
            }
        }
        let edges = std::iter::once(&fence)
            .chain(cutouts.iter())
            .flat_map(|poly| poly.edges())
            .map(|(a, b)| Edge {
                a,
                b,
                bbox: BBox {
                    min: Point::new(a.x.min(b.x), a.y.min(b.y)),
                    max: Point::new(a.x.max(b.x), a.y.max(b.y)),
                },
            })
            .collect();
        Ok(Self {
            fence,
            cutouts,
            edges,
        })
    }

    /// The outer polygon.
    pub fn fence(&self) -> &Polygon {
        &self.fence
    }

    /// The polygons inside the fence that must not be entered.
    pub fn cutouts(&self) -> &[Polygon] {
        &self.cutouts
    }

    /// Every boundary edge, fence first, then each cutout's.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The fence's bounding box.
    pub fn bbox(&self) -> BBox {
        self.fence.bbox()
    }

    /// Drivable area in square metres (fence minus cutouts).
    pub fn drivable_area(&self) -> f64 {
        self.fence.area() - self.cutouts.iter().map(Polygon::area).sum::<f64>()
    }

    /// Whether `p` is strictly inside the drivable region (inside the fence, outside every cutout,
    /// on no boundary).
    pub fn contains_point(&self, p: Point) -> bool {
        self.fence.contains(p)
            && !self.cutouts.iter().any(|c| c.contains(p))
            && !self.on_boundary(p)
    }

    fn on_boundary(&self, p: Point) -> bool {
        self.edges
            .iter()
            .any(|e| e.bbox.contains(p) && orient(e.a, e.b, p) == 0.0)
    }

    /// Whether the whole closed segment `a–b` lies in the drivable region: `a` is inside and the
    /// segment meets no boundary edge (so `b` is inside too).
    pub fn contains_segment(&self, a: Point, b: Point) -> bool {
        self.contains_point(a) && !self.segment_meets_boundary(a, b)
    }

    /// Whether the closed segment `a–b` shares a point with any boundary edge.
    pub fn segment_meets_boundary(&self, a: Point, b: Point) -> bool {
        let sb = BBox {
            min: Point::new(a.x.min(b.x), a.y.min(b.y)),
            max: Point::new(a.x.max(b.x), a.y.max(b.y)),
        };
        self.edges
            .iter()
            .any(|e| e.bbox.overlaps(&sb) && segments_intersect(a, b, e.a, e.b))
    }

    /// The point where the ray `origin → end` first meets the boundary (the *closest* hit), or
    /// `end` when it meets none.
    pub fn clip_ray(&self, origin: Point, end: Point) -> Point {
        let rb = BBox {
            min: Point::new(origin.x.min(end.x), origin.y.min(end.y)),
            max: Point::new(origin.x.max(end.x), origin.y.max(end.y)),
        };
        let t = self
            .edges
            .iter()
            .filter(|e| e.bbox.overlaps(&rb))
            .filter_map(|e| segment_hit(origin, end, e.a, e.b))
            .fold(1.0_f64, f64::min);
        origin + (end - origin) * t
    }

    /// Distance from `p` to the nearest boundary edge (fence or cutout).
    pub fn boundary_distance(&self, p: Point) -> f64 {
        self.edges
            .iter()
            .map(|e| point_segment_distance(p, e.a, e.b))
            .fold(f64::INFINITY, f64::min)
    }

    /// Distance from the segment `a–b` to the nearest boundary edge (zero when it meets one).
    pub fn segment_boundary_distance(&self, a: Point, b: Point) -> f64 {
        self.edges
            .iter()
            .map(|e| segment_segment_distance(a, b, e.a, e.b))
            .fold(f64::INFINITY, f64::min)
    }

    /// The distance from the segment `a–b` to the nearest boundary edge when it is less than
    /// `limit`, or `None` when every edge keeps at least `limit` away: the clearance check.
    ///
    /// Same answer as comparing [`Self::segment_boundary_distance`] with `limit`, but edges
    /// whose bounding box lies farther than `limit` from the segment's are skipped (they cannot
    /// be nearer), so the hot loop measures only the few edges close by.
    pub fn segment_boundary_distance_below(&self, a: Point, b: Point, limit: f64) -> Option<f64> {
        let near = BBox {
            min: Point::new(a.x.min(b.x) - limit, a.y.min(b.y) - limit),
            max: Point::new(a.x.max(b.x) + limit, a.y.max(b.y) + limit),
        };
        let nearest = self
            .edges
            .iter()
            .filter(|e| e.bbox.overlaps(&near))
            .map(|e| segment_segment_distance(a, b, e.a, e.b))
            .fold(f64::INFINITY, f64::min);
        (nearest < limit).then_some(nearest)
    }
}

/// Whether any edge of `p` meets any edge of `q`.
fn polygons_touch(p: &Polygon, q: &Polygon) -> bool {
    p.bbox().overlaps(&q.bbox())
        && p.edges()
            .any(|(a, b)| q.edges().any(|(c, d)| segments_intersect(a, b, c, d)))
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    /// Every pair compared: what the grid must agree with.
    fn first_self_intersection_by_every_pair(vertices: &[Point]) -> Option<(usize, usize)> {
        let n = vertices.len();
        let edges: Vec<(Point, Point)> = closed_edges(vertices).collect();
        for i in 0..n {
            for j in (i + 1)..n {
                let (a, b) = edges[i];
                let (c, d) = edges[j];
                let bad = if j == i + 1 || (i == 0 && j == n - 1) {
                    let (shared, p, q) = if j == i + 1 { (b, a, d) } else { (a, b, c) };
                    orient(p, shared, q) == 0.0 && (p - shared).dot(q - shared) > 0.0
                } else {
                    segments_intersect(a, b, c, d)
                };
                if bad {
                    return Some((i, j));
                }
            }
        }
        None
    }

    /// The crossing-number test over every edge, each with its orientation: what
    /// [`Polygon::contains`], which skips the edges above or below the point, must agree with.
    fn contains_by_every_edge(polygon: &Polygon, p: Point) -> bool {
        let mut inside = false;
        for (a, b) in polygon.edges() {
            let o = orient(a, b, p);
            if o == 0.0 && on_segment(a, b, p) {
                return true;
            }
            if (a.y > p.y) != (b.y > p.y) && (o > 0.0) == (b.y > a.y) {
                inside = !inside;
            }
        }
        inside
    }

    proptest! {
        /// `contains` agrees with the test over every edge on star-shaped polygons on a grid,
        /// for points anywhere, on vertices, on edges and level with vertices.
        #[test]
        fn contains_agrees_with_the_test_over_every_edge(
            n in 3usize..40,
            radii in proptest::collection::vec(1i32..10, 40),
            points in proptest::collection::vec((-12i32..12, -12i32..12), 50),
            halves in proptest::collection::vec((0usize..40, 0u8..3), 20),
        ) {
            let vertices: Vec<Point> = (0..n)
                .map(|k| {
                    let t = std::f64::consts::TAU * k as f64 / n as f64;
                    let r = f64::from(radii[k]);
                    Point::new((r * t.cos()).round(), (r * t.sin()).round())
                })
                .collect();
            let Ok(polygon) = Polygon::new(vertices) else {
                return Ok(());
            };
            let v = polygon.vertices();
            let mut probes: Vec<Point> =
                points.iter().map(|&(x, y)| Point::new(f64::from(x), f64::from(y))).collect();
            for &(k, at) in &halves {
                let (a, b) = (v[k % v.len()], v[(k + 1) % v.len()]);
                probes.push(match at {
                    0 => a,
                    1 => Point::new((a.x + b.x) / 2.0, (a.y + b.y) / 2.0),
                    _ => Point::new(a.x + 0.25, a.y),
                });
            }
            for p in probes {
                prop_assert_eq!(polygon.contains(p), contains_by_every_edge(&polygon, p), "{:?}", p);
            }
        }

        /// The grid finds the same first pair as comparing every pair: on star-shaped polygons
        /// (simple, or not when a spike crosses) and on random vertices (crossing everywhere).
        #[test]
        fn the_grid_finds_the_same_first_self_intersection(
            n in 64usize..400,
            radii in proptest::collection::vec(1.0f64..10.0, 400),
            jitter in proptest::collection::vec(-0.2f64..0.2, 400),
            random in proptest::collection::vec((-5i32..5, -5i32..5), 400),
            star in any::<bool>(),
        ) {
            let vertices: Vec<Point> = if star {
                (0..n)
                    .map(|k| {
                        let t = std::f64::consts::TAU * (k as f64 + jitter[k]) / n as f64;
                        Point::new(radii[k] * t.cos(), radii[k] * t.sin())
                    })
                    .collect()
            } else {
                random[..n].iter().map(|&(x, y)| Point::new(f64::from(x), f64::from(y))).collect()
            };
            prop_assert_eq!(
                first_self_intersection(&vertices),
                first_self_intersection_by_every_pair(&vertices)
            );
        }
    }

    use super::*;

    fn square(x0: f64, y0: f64, side: f64) -> Polygon {
        crate::test_support::rect(x0, y0, x0 + side, y0 + side)
    }

    #[test]
    fn crossing_and_touching_segments_intersect() {
        let p = Point::new;
        assert!(segments_intersect(
            p(0., 0.),
            p(2., 2.),
            p(0., 2.),
            p(2., 0.)
        ));
        assert!(segments_intersect(
            p(0., 0.),
            p(1., 1.),
            p(1., 1.),
            p(2., 0.)
        ));
        assert!(segments_intersect(
            p(0., 0.),
            p(2., 0.),
            p(1., 0.),
            p(3., 0.)
        ));
        assert!(!segments_intersect(
            p(0., 0.),
            p(1., 0.),
            p(2., 0.),
            p(3., 0.)
        ));
        assert!(!segments_intersect(
            p(0., 0.),
            p(1., 1.),
            p(0., 1.),
            p(0.4, 0.6)
        ));
    }

    #[test]
    fn polygon_is_closed_and_contains_by_crossings() {
        let sq = square(0., 0., 10.);
        assert_eq!(sq.edges().count(), 4);
        assert!(sq.contains(Point::new(5., 5.)));
        assert!(sq.contains(Point::new(0., 5.)), "boundary counts as inside");
        assert!(!sq.contains(Point::new(10.1, 5.)));
        assert!((sq.area() - 100.0).abs() < 1e-12);
    }

    #[test]
    fn bow_tie_is_self_intersecting() {
        let err = Polygon::new(vec![
            Point::new(0., 0.),
            Point::new(1., 1.),
            Point::new(1., 0.),
            Point::new(0., 1.),
        ])
        .unwrap_err();
        assert_eq!(
            err,
            PolygonError::SelfIntersecting {
                first: 0,
                second: 2
            }
        );
    }

    #[test]
    fn closing_edge_is_tested() {
        // The closing edge (3 → 0) crosses edge 1: only a closed-polygon test catches it.
        let err = Polygon::new(vec![
            Point::new(0., 0.),
            Point::new(4., 0.),
            Point::new(0., 4.),
            Point::new(4., 4.),
        ])
        .unwrap_err();
        assert!(matches!(err, PolygonError::SelfIntersecting { .. }));
    }

    #[test]
    fn segment_through_cutout_is_rejected_even_with_both_ends_outside_it() {
        let area = Area::new(square(0., 0., 10.), vec![square(4., 4., 2.)]).unwrap();
        assert!(area.contains_point(Point::new(3., 5.)));
        assert!(area.contains_point(Point::new(7., 5.)));
        assert!(!area.contains_segment(Point::new(3., 5.), Point::new(7., 5.)));
        assert!(area.contains_segment(Point::new(1., 1.), Point::new(3., 1.)));
        assert!(!area.contains_point(Point::new(5., 5.)));
    }

    #[test]
    fn ray_is_clipped_at_the_closest_hit() {
        let area = Area::new(square(0., 0., 10.), vec![square(4., 4., 2.)]).unwrap();
        // Crosses the cutout's near side at x = 4 and the far side and fence further on.
        let hit = area.clip_ray(Point::new(1., 5.), Point::new(20., 5.));
        assert!((hit.x - 4.0).abs() < 1e-12 && (hit.y - 5.0).abs() < 1e-12);
        let free = area.clip_ray(Point::new(1., 1.), Point::new(2., 1.));
        assert_eq!(free, Point::new(2., 1.));
    }

    #[test]
    fn cutout_errors_name_the_cutout() {
        let err = Area::new(square(0., 0., 10.), vec![square(8., 8., 4.)]).unwrap_err();
        assert_eq!(err, AreaError::CutoutOutsideFence { index: 0 });
        let err = Area::new(
            square(0., 0., 10.),
            vec![square(1., 1., 3.), square(2., 2., 3.)],
        )
        .unwrap_err();
        assert_eq!(
            err,
            AreaError::CutoutsOverlap {
                first: 0,
                second: 1
            }
        );
    }

    #[test]
    fn turn_angle_wraps() {
        let d = turn_angle(3.0, -3.0);
        assert!((d - (std::f64::consts::TAU - 6.0)).abs() < 1e-12);
    }
}
