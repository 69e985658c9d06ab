//! Polyline helpers: length, validity of a piece of route, interpolation.

use trajgen::{Area, Constraints, Point, Pose, check_route};

/// Distance between two points (a square root of the dot product: faster than `hypot`, and
/// exact enough for planning; validity is always decided by [`trajgen::check_route`]).
pub(crate) fn distance(a: Point, b: Point) -> f64 {
    let d = b - a;
    d.dot(d).sqrt()
}

/// Total length of a polyline.
pub(crate) fn length(points: &[Point]) -> f64 {
    points.windows(2).map(|w| distance(w[0], w[1])).sum()
}

/// Whether the piece `from.position → piece… → next` is drivable: every segment and turn, the
/// turn from `from.heading` into the first segment and the turn into `next` included.
pub(crate) fn piece_is_valid(
    area: &Area,
    c: &Constraints,
    from: Pose,
    piece: &[Point],
    next: Point,
) -> bool {
    let mut points = Vec::with_capacity(piece.len() + 2);
    points.push(from.position);
    points.extend_from_slice(piece);
    points.push(next);
    check_route(area, &points, c, Some(from.heading)).is_ok()
}

/// Whether the single segment `a → b` lies in the area with the clearance (lengths and turns are
/// the caller's business).
pub(crate) fn segment_is_clear(area: &Area, c: &Constraints, a: Point, b: Point) -> bool {
    area.contains_segment(a, b)
        && (c.clearance <= 0.0
            || area
                .segment_boundary_distance_below(a, b, c.clearance)
                .is_none())
}

/// The points strictly between `a` and `b` that split the straight `a → b` into the fewest equal
/// pieces no longer than `max_piece`.
pub(crate) fn split_points(a: Point, b: Point, max_piece: f64) -> impl Iterator<Item = Point> {
    let pieces = (a.dist(b) / max_piece).ceil().max(1.0) as usize;
    (1..pieces).map(move |i| a + (b - a) * (i as f64 / pieces as f64))
}

/// The polyline with every segment longer than `max_piece` split into equal pieces.
pub(crate) fn interpolate(points: &[Point], max_piece: f64) -> Vec<Point> {
    let mut out = Vec::with_capacity(points.len() * 2);
    for w in points.windows(2) {
        out.push(w[0]);
        out.extend(split_points(w[0], w[1], max_piece));
    }
    out.extend(points.last());
    out
}

/// The heading of the car arriving at point `i` of `route` (the car's own heading at point 0).
pub(crate) fn heading_at(start: Pose, route: &[Point], i: usize) -> f64 {
    if i == 0 {
        start.heading
    } else {
        (route[i] - route[i - 1]).heading()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_splits_only_long_segments_into_equal_pieces() {
        let p = Point::new;
        let route = [p(0.0, 0.0), p(1.0, 0.0), p(4.0, 0.0)];
        let out = interpolate(&route, 1.5);
        assert_eq!(
            out,
            vec![p(0.0, 0.0), p(1.0, 0.0), p(2.5, 0.0), p(4.0, 0.0)]
        );
        assert!((length(&out) - 4.0).abs() < 1e-12);
    }
}
