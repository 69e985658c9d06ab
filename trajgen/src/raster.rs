//! The area on a square grid: which cells are drivable.
//!
//! A [`Raster`] covers the fence's bounding box with square cells from its lower-left corner; a
//! cell is *drivable* when its centre is strictly inside the drivable region
//! ([`Area::contains_point`]: inside the fence, outside every cutout, on no boundary). Area
//! validation's coverage grid counts visits over it and the return-route search spreads its
//! distances over it.
//!
//! The cells are found row by row with scanlines: the edges crossing the row's centre line give
//! the stretches between crossings that lie inside (even–odd rule; cutouts never overlap and lie
//! strictly inside the fence). A cell whose centre lies so close to a crossing, or to an edge
//! touching the line, that floating-point rounding could put it on the wrong side is decided
//! with the exact [`Area::contains_point`]; so the raster is exactly the cells with a drivable
//! centre, at the cost of a few exact tests per row.

use crate::geometry::{Area, Point};

/// The most cells a raster has (4 million: 4 MB of flags, and a coverage grid's 16 MB of visit
/// counts). A fence whose bounding box would need more cells of the size asked for gets larger
/// cells ([`Raster::cell_size`] says which); a real test area at 0.5 m has tens of thousands.
pub const MAX_CELLS: usize = 4_000_000;

/// A square grid over an area's fence bounding box, row-major (`row * cols + col`), cell (0, 0)
/// at the lower-left corner.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Lower-left corner of cell (0, 0): the fence bounding box's.
    pub origin: Point,
    /// Side of a cell, metres: the size asked for, or larger in a huge area ([`MAX_CELLS`]).
    pub cell_size: f64,
    /// Cells along x (at least 1).
    pub cols: usize,
    /// Cells along y (at least 1).
    pub rows: usize,
    /// Per cell: whether its centre is drivable.
    pub drivable: Vec<bool>,
}

impl Raster {
    /// The raster of `area` with cells of `cell_size` metres (positive): `⌈width / cell_size⌉`
    /// columns and `⌈height / cell_size⌉` rows of the fence's bounding box, at least one each.
    /// Where that would be more than [`MAX_CELLS`] cells (a huge area: whatever its coordinates,
    /// the raster's size is bounded), the cells are made larger until it is not.
    pub fn new(area: &Area, cell_size: f64) -> Self {
        let bbox = area.bbox();
        // Each extent as half the difference of halves: finite even between ±f64::MAX.
        let cells_along = |low: f64, high: f64, cell: f64| {
            let cells = ((high * 0.5 - low * 0.5) / (cell * 0.5)).ceil();
            if cells.is_finite() {
                cells.max(1.0)
            } else {
                f64::INFINITY
            }
        };
        let mut cell_size = cell_size;
        let fits = |cell: f64| {
            cells_along(bbox.min.x, bbox.max.x, cell) * cells_along(bbox.min.y, bbox.max.y, cell)
                <= MAX_CELLS as f64
        };
        if !fits(cell_size) {
            // From the size that would fit were the cells' count not rounded up, grown a little
            // at a time (a step or two); the loop ends since the extents are finite.
            let (half_width, half_height) = (
                bbox.max.x * 0.5 - bbox.min.x * 0.5,
                bbox.max.y * 0.5 - bbox.min.y * 0.5,
            );
            let n = MAX_CELLS as f64;
            let least = (half_width.sqrt() * half_height.sqrt() / n.sqrt() * 2.0)
                .max(half_width / n * 2.0)
                .max(half_height / n * 2.0);
            if least.is_finite() && least > cell_size {
                cell_size = least;
            }
            while !fits(cell_size) && cell_size < f64::MAX {
                cell_size = (cell_size * 1.0625).min(f64::MAX);
            }
        }
        // At most MAX_CELLS in all (NaN, from a NaN cell size, casts to 0: one cell).
        let cols = (cells_along(bbox.min.x, bbox.max.x, cell_size) as usize).clamp(1, MAX_CELLS);
        let rows =
            (cells_along(bbox.min.y, bbox.max.y, cell_size) as usize).clamp(1, MAX_CELLS / cols);
        let mut raster = Self {
            origin: bbox.min,
            cell_size,
            cols,
            rows,
            drivable: vec![false; cols * rows],
        };
        // Coordinates and their rounding errors scale with the largest magnitude in play.
        let scale = 1.0
            + [bbox.min.x, bbox.min.y, bbox.max.x, bbox.max.y]
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
        let mut crossings = Vec::new();
        let mut doubtful = Vec::new();
        for row in 0..rows {
            let y = raster.cell_centre(0, row).y;
            crossings.clear();
            doubtful.clear();
            for e in area.edges() {
                if (e.a.y > y) != (e.b.y > y) {
                    let slope = (e.b.x - e.a.x) / (e.b.y - e.a.y);
                    let x = e.a.x + (y - e.a.y) * slope;
                    crossings.push(x);
                    let tolerance = 1e-12 * scale * (4.0 + slope.abs());
                    doubtful.push((x - tolerance, x + tolerance));
                } else if e.a.y.max(e.b.y) == y {
                    // An edge ending on the line (or lying along it) crosses nothing there.
                    let tolerance = 1e-12 * scale;
                    doubtful.push((e.a.x.min(e.b.x) - tolerance, e.a.x.max(e.b.x) + tolerance));
                }
            }
            crossings.sort_by(f64::total_cmp);
            for pair in crossings.chunks_exact(2) {
                if let Some((first, last)) = raster.columns_between(pair[0], pair[1]) {
                    raster.drivable[row * cols + first..=row * cols + last].fill(true);
                }
            }
            for &(from, to) in &doubtful {
                if let Some((first, last)) = raster.columns_between(from, to) {
                    for col in first..=last {
                        let centre = raster.cell_centre(col, row);
                        raster.drivable[row * cols + col] = area.contains_point(centre);
                    }
                }
            }
        }
        raster
    }

    /// The columns whose centres lie in `from..=to` (x), if any.
    fn columns_between(&self, from: f64, to: f64) -> Option<(usize, usize)> {
        let first = ((from - self.origin.x) / self.cell_size - 0.5)
            .ceil()
            .max(0.0);
        let last = ((to - self.origin.x) / self.cell_size - 0.5).floor();
        if last < first || first >= self.cols as f64 {
            return None;
        }
        Some((first as usize, (last as usize).min(self.cols - 1)))
    }

    /// The centre of cell (`col`, `row`).
    pub fn cell_centre(&self, col: usize, row: usize) -> Point {
        self.origin
            + Point::new(
                (col as f64 + 0.5) * self.cell_size,
                (row as f64 + 0.5) * self.cell_size,
            )
    }

    /// The (column, row) of the cell `p` lies in, outside the grid too (negative or past the
    /// last); cells are closed below and open above.
    pub fn cell_of(&self, p: Point) -> (i64, i64) {
        let col = ((p.x - self.origin.x) / self.cell_size).floor();
        let row = ((p.y - self.origin.y) / self.cell_size).floor();
        (col as i64, row as i64)
    }

    /// The index (`row * cols + col`) of the cell `p` lies in; `None` outside the grid or for a
    /// non-finite `p`.
    pub fn index_of(&self, p: Point) -> Option<usize> {
        let col = ((p.x - self.origin.x) / self.cell_size).floor();
        let row = ((p.y - self.origin.y) / self.cell_size).floor();
        let inside = col >= 0.0 && row >= 0.0 && col < self.cols as f64 && row < self.rows as f64;
        inside.then(|| row as usize * self.cols + col as usize)
    }

    /// The index of cell (`col`, `row`), `None` outside the grid.
    pub fn index(&self, col: i64, row: i64) -> Option<usize> {
        let inside = (0..self.cols as i64).contains(&col) && (0..self.rows as i64).contains(&row);
        inside.then(|| row as usize * self.cols + col as usize)
    }

    /// Number of drivable cells.
    pub fn drivable_cells(&self) -> usize {
        self.drivable.iter().filter(|&&d| d).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{l_shape, polygon, real_areas, rect, square_with_cutouts};
    use proptest::prelude::*;

    /// The raster cell by cell with the exact test.
    fn exact(area: &Area, cell_size: f64) -> Vec<bool> {
        let raster = Raster::new(area, cell_size);
        (0..raster.rows)
            .flat_map(|row| (0..raster.cols).map(move |col| (col, row)))
            .map(|(col, row)| area.contains_point(raster.cell_centre(col, row)))
            .collect()
    }

    #[test]
    fn only_cells_with_a_drivable_centre_are_drivable() {
        let area = Area::new(rect(0.0, 0.0, 4.0, 4.0), vec![rect(1.0, 1.0, 3.0, 3.0)]).unwrap();
        let raster = Raster::new(&area, 1.0);
        assert_eq!(
            (raster.cols, raster.rows, raster.drivable_cells()),
            (4, 4, 12)
        );
        assert!(!raster.drivable[raster.index_of(Point::new(1.5, 2.5)).unwrap()]);
        assert!(raster.drivable[raster.index_of(Point::new(0.5, 2.5)).unwrap()]);
    }

    #[test]
    fn centres_on_an_edge_or_a_vertex_are_not_drivable() {
        // Edges along the centre lines x = 2.5 and y = 1.5, a vertex on the centre (2.5, 3.5), a
        // diagonal edge x + y = 6 through the centres (0.5, 5.5) and (1.5, 4.5).
        let fence = polygon(&[
            [0., 0.],
            [6., 0.],
            [6., 1.5],
            [2.5, 1.5],
            [2.5, 3.5],
            [0., 6.],
        ]);
        let area = Area::new(fence, vec![]).unwrap();
        let raster = Raster::new(&area, 1.0);
        assert_eq!(raster.drivable, exact(&area, 1.0));
        assert!(!raster.drivable[raster.index_of(Point::new(2.5, 2.5)).unwrap()]);
        assert!(!raster.drivable[raster.index_of(Point::new(4.5, 1.5)).unwrap()]);
        assert!(!raster.drivable[raster.index_of(Point::new(2.5, 3.5)).unwrap()]);
        assert!(!raster.drivable[raster.index_of(Point::new(1.5, 4.5)).unwrap()]);
        assert!(raster.drivable[raster.index_of(Point::new(1.5, 2.5)).unwrap()]);
    }

    #[test]
    fn the_raster_is_the_exact_test_on_every_fixture() {
        let mut fixtures = real_areas();
        fixtures.push(square_with_cutouts());
        fixtures.push(l_shape());
        for f in fixtures {
            for cell in [0.25, 0.5, 1.0, 0.37] {
                assert_eq!(
                    Raster::new(&f.area, cell).drivable,
                    exact(&f.area, cell),
                    "{} at {cell} m",
                    f.name
                );
            }
        }
    }

    #[test]
    fn cells_and_indices() {
        let area = Area::new(rect(-2.0, 1.0, 2.0, 3.0), vec![]).unwrap();
        let raster = Raster::new(&area, 0.5);
        assert_eq!((raster.cols, raster.rows), (8, 4));
        assert_eq!(raster.cell_centre(0, 0), Point::new(-1.75, 1.25));
        assert_eq!(raster.cell_of(Point::new(-2.0, 1.0)), (0, 0));
        assert_eq!(raster.cell_of(Point::new(-2.1, 0.9)), (-1, -1));
        assert_eq!(raster.index_of(Point::new(1.9, 2.9)), Some(31));
        assert_eq!(raster.index_of(Point::new(2.0, 2.0)), None);
        assert_eq!(raster.index_of(Point::new(f64::NAN, 2.0)), None);
        assert_eq!(raster.index(7, 3), Some(31));
        assert_eq!(raster.index(8, 0), None);
        assert_eq!(raster.index(0, -1), None);
    }

    /// Fences far beyond any test area (`1e155`, where squares overflow and the area is NaN, up
    /// to ±f64::MAX), built directly: a raster, a coverage grid and its traversal of any segment
    /// stay bounded and never panic, and area validation returns.
    #[test]
    fn a_huge_or_far_away_area_gets_a_bounded_raster_without_panicking() {
        use crate::validation::{CoverageGrid, ValidationConfig, validate_area};
        let m = f64::MAX;
        let fences: [&[[f64; 2]]; 6] = [
            &[[0., 0.], [1e155, 0.], [10., 10.], [0., 10.]],
            &[[0., 0.], [1e155, 0.], [1e155, 1e155], [0., 1e155]],
            &[[-m, -m], [m, -m], [m, m], [-m, m]],
            &[[0., 0.], [1e6, 0.], [1e6, 1e6], [0., 1e6]],
            &[[1e300, -1e300], [1e308, 0.], [1e300, 1e300]],
            &[[0., 0.], [1e-300, 0.], [0., 1e300]],
        ];
        for fence in fences {
            let fence = polygon(fence);
            let area = Area::new(fence.clone(), vec![]).unwrap();
            for cell in [0.5, 1e-300, 1e300] {
                let raster = Raster::new(&area, cell);
                assert!(raster.cols >= 1 && raster.rows >= 1, "{fence:?}");
                assert!(
                    raster.cols * raster.rows <= MAX_CELLS,
                    "{fence:?} at {cell}"
                );
                assert_eq!(raster.drivable.len(), raster.cols * raster.rows);
                assert!(raster.cell_size >= cell, "{fence:?} at {cell}");
            }
            let mut grid = CoverageGrid::new(&area, 0.5);
            let v = fence.vertices();
            for (a, b) in [
                (v[0], v[1]),
                (v[1], v[2]),
                (Point::new(-m, 0.0), Point::new(m, 1.0)),
                (Point::new(-m, -m), Point::new(m, m)),
                (Point::new(f64::NAN, 0.0), Point::new(1.0, 1.0)),
                (Point::new(5.0, 5.0), Point::new(f64::INFINITY, 5.0)),
            ] {
                grid.visit_segment(a, b);
            }
            assert!(grid.coverage() <= 1.0);
            let start = [
                Point::new(2.0, 2.0),
                Point::new(3.5, 2.0),
                Point::new(5.0, 2.0),
            ];
            let config = ValidationConfig::default().with_km(0.01);
            let mut rng = rand_pcg::Pcg64Mcg::new(7);
            let _ = validate_area(&area, &start, &config, &mut rng, &mut |_| {});
        }
    }

    proptest! {
        /// Random star-shaped fences of 3–5 corners, with a square cutout when it fits, at random
        /// places, cell sizes and on a grid that puts corners on cell centres.
        #[test]
        fn the_raster_is_the_exact_test(
            origin in (-1e4f64..1e4, -1e4f64..1e4),
            corners in prop::collection::vec((0.0f64..40.0, 0.0f64..40.0), 3..6),
            cutout in (5.0f64..30.0, 5.0f64..30.0, 0.5f64..6.0),
            cell in 0.1f64..3.0,
            snapped in any::<bool>(),
        ) {
            // Snapped, every coordinate lies on a quarter metre: on the centres of 0.5 m cells.
            let (ox, oy) = if snapped { (origin.0.round(), origin.1.round()) } else { origin };
            let snap = |v: f64| if snapped { (v * 4.0).round() / 4.0 } else { v };
            let cell = if snapped { 0.5 } else { cell };
            let mut corners: Vec<(f64, f64)> =
                corners.into_iter().map(|(x, y)| (snap(x), snap(y))).collect();
            // A star-shaped polygon: the corners sorted by angle around the box's centre.
            corners.sort_by(|a, b| {
                (a.1 - 20.0).atan2(a.0 - 20.0).total_cmp(&(b.1 - 20.0).atan2(b.0 - 20.0))
            });
            let fence: Vec<[f64; 2]> = corners.iter().map(|&(x, y)| [ox + x, oy + y]).collect();
            let Ok(fence) = crate::geometry::Polygon::new(fence.iter().map(|&p| p.into()).collect())
            else {
                return Ok(());
            };
            let (cx, cy, side) = (snap(cutout.0) + ox, snap(cutout.1) + oy, snap(cutout.2).max(0.25));
            let square = crate::geometry::Polygon::new(vec![
                Point::new(cx, cy),
                Point::new(cx + side, cy),
                Point::new(cx + side, cy + side),
                Point::new(cx, cy + side),
            ])
            .expect("a square");
            let area = Area::new(fence.clone(), vec![square]).or_else(|_| Area::new(fence, vec![]));
            let Ok(area) = area else {
                return Ok(());
            };
            prop_assert_eq!(Raster::new(&area, cell).drivable, exact(&area, cell));
        }
    }
}
