//! The search's heuristic: distance to go around the obstacles, over a grid.
//!
//! The area is rasterised into square cells ([`trajgen::Raster`]: a cell is free when its centre
//! is inside the drivable region), and Dijkstra's algorithm spreads from the joins'
//! cells (each seeded with the recovery route left after it) over 8-connected free cells, with no
//! diagonal step past a blocked cell. The result ignores headings and turning; it steers the
//! search around cutouts and walls instead of into them.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use trajgen::{Area, Point, Raster};

use crate::join::Join;

/// Most cells of a grid (a 1 km² area still gets 0.5 m cells).
const MAX_CELLS: f64 = 4.0e6;

/// Distance to go from every free cell to the recovery route.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DistanceGrid {
    /// The free cells: the area's drivable ones and the joins'.
    raster: Raster,
    cost: Vec<f64>,
}

/// A Dijkstra queue entry (smallest cost first).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    cost: f64,
    index: usize,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost
            .total_cmp(&self.cost)
            .then_with(|| other.index.cmp(&self.index))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl DistanceGrid {
    /// The grid of `area` with cells of `cell` metres (larger in a huge area: at most
    /// [`MAX_CELLS`] cells), distances to `joins`.
    pub fn new(area: &Area, joins: &[Join], cell: f64) -> Self {
        let (width, height) = area.bbox().size();
        let raster = Raster::new(area, cell.max((width * height / MAX_CELLS).sqrt()));
        let mut grid = Self {
            cost: vec![f64::INFINITY; raster.drivable.len()],
            raster,
        };
        grid.spread(joins);
        grid
    }

    /// Distance to go from `p` (the cost of its cell; infinite outside the grid or where the
    /// recovery route cannot be reached).
    pub fn at(&self, p: Point) -> f64 {
        self.raster
            .index_of(p)
            .map_or(f64::INFINITY, |i| self.cost[i])
    }

    /// Dijkstra from the joins' cells over free cells.
    fn spread(&mut self, joins: &[Join]) {
        let mut queue = BinaryHeap::new();
        for join in joins {
            if let Some(i) = self.raster.index_of(join.point)
                && join.remaining < self.cost[i]
            {
                self.raster.drivable[i] = true;
                self.cost[i] = join.remaining;
                queue.push(Entry {
                    cost: join.remaining,
                    index: i,
                });
            }
        }
        while let Some(Entry { cost, index }) = queue.pop() {
            if cost > self.cost[index] {
                continue;
            }
            let neighbours: Vec<(usize, f64)> = self.neighbours(index).collect();
            for (next, step) in neighbours {
                let candidate = cost + step;
                if candidate < self.cost[next] {
                    self.cost[next] = candidate;
                    queue.push(Entry {
                        cost: candidate,
                        index: next,
                    });
                }
            }
        }
    }

    /// Free 8-neighbours of cell `index` with the step length; no diagonal past a blocked cell.
    fn neighbours(&self, index: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let cols = self.raster.cols;
        let (row, col) = ((index / cols) as i64, (index % cols) as i64);
        let free_cell =
            move |r: i64, c: i64| self.raster.index(c, r).filter(|&i| self.raster.drivable[i]);
        let free = move |r: i64, c: i64| free_cell(r, c).is_some();
        const MOVES: [(i64, i64); 8] = [
            (0, 1),
            (1, 0),
            (0, -1),
            (-1, 0),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ];
        MOVES.into_iter().filter_map(move |(dr, dc)| {
            let (r, c) = (row + dr, col + dc);
            let diagonal = dr != 0 && dc != 0;
            let open = !diagonal || (free(row + dr, col) && free(row, col + dc));
            let step = if diagonal {
                self.raster.cell_size * std::f64::consts::SQRT_2
            } else {
                self.raster.cell_size
            };
            free_cell(r, c).filter(|_| open).map(|i| (i, step))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trajgen::Polygon;

    fn square(x0: f64, y0: f64, side: f64) -> Polygon {
        Polygon::new(vec![
            Point::new(x0, y0),
            Point::new(x0 + side, y0),
            Point::new(x0 + side, y0 + side),
            Point::new(x0, y0 + side),
        ])
        .unwrap()
    }

    #[test]
    fn the_distance_goes_around_a_cutout() {
        // A wall-like cutout between the car's side and the join, open on the left only.
        let wall = Polygon::new(vec![
            Point::new(1.0, 9.0),
            Point::new(19.9, 9.0),
            Point::new(19.9, 11.0),
            Point::new(1.0, 11.0),
        ])
        .unwrap();
        let area = Area::new(square(0.0, 0.0, 20.0), vec![wall]).unwrap();
        let join = Join {
            segment: 0,
            point: Point::new(15.0, 5.0),
            next: Point::new(16.0, 5.0),
            remaining: 1.0,
        };
        let grid = DistanceGrid::new(&area, &[join], 0.5);
        let behind = Point::new(15.0, 15.0);
        let straight = behind.dist(join.point) + 1.0;
        let around = grid.at(behind);
        assert!(around > straight + 15.0, "{around} vs {straight}");
        assert!(
            grid.at(Point::new(10.0, 10.0)).is_infinite(),
            "inside the cutout"
        );
        assert!((grid.at(Point::new(15.2, 5.2)) - 1.0).abs() < 1e-9);
    }
}
