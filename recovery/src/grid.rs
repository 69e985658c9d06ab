//! The search's heuristic: distance to go around the obstacles, over a grid.
//!
//! The area is rasterised into square cells (a cell is free when its centre is inside the fence
//! and outside every cutout, found by scanlines), and Dijkstra's algorithm spreads from the joins'
//! cells (each seeded with the recovery route left after it) over 8-connected free cells, with no
//! diagonal step past a blocked cell. The result ignores headings and turning; it steers the
//! search around cutouts and walls instead of into them.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use trajgen::{Area, Point};

use crate::join::Join;

/// Most cells of a grid (a 1 km² area still gets 0.5 m cells).
const MAX_CELLS: f64 = 4.0e6;

/// Distance to go from every free cell to the recovery route.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DistanceGrid {
    origin: Point,
    cell: f64,
    cols: usize,
    rows: usize,
    free: Vec<bool>,
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
        let bbox = area.bbox();
        let (width, height) = bbox.size();
        let cell = cell.max((width * height / MAX_CELLS).sqrt());
        let cols = ((width / cell).ceil() as usize).max(1);
        let rows = ((height / cell).ceil() as usize).max(1);
        let mut grid = Self {
            origin: bbox.min,
            cell,
            cols,
            rows,
            free: vec![false; cols * rows],
            cost: vec![f64::INFINITY; cols * rows],
        };
        grid.rasterise(area);
        grid.spread(joins);
        grid
    }

    /// Distance to go from `p` (the cost of its cell; infinite outside the grid or where the
    /// recovery route cannot be reached).
    pub fn at(&self, p: Point) -> f64 {
        self.index_of(p).map_or(f64::INFINITY, |i| self.cost[i])
    }

    fn index_of(&self, p: Point) -> Option<usize> {
        let col = ((p.x - self.origin.x) / self.cell).floor();
        let row = ((p.y - self.origin.y) / self.cell).floor();
        let inside = col >= 0.0 && row >= 0.0 && col < self.cols as f64 && row < self.rows as f64;
        inside.then(|| row as usize * self.cols + col as usize)
    }

    /// Marks cells whose centre lies inside the area, row by row (even–odd rule over every edge
    /// of the fence and the cutouts).
    fn rasterise(&mut self, area: &Area) {
        let mut crossings = Vec::new();
        for row in 0..self.rows {
            let y = self.origin.y + (row as f64 + 0.5) * self.cell;
            crossings.clear();
            for e in area.edges() {
                if (e.a.y > y) != (e.b.y > y) {
                    crossings.push(e.a.x + (y - e.a.y) * (e.b.x - e.a.x) / (e.b.y - e.a.y));
                }
            }
            crossings.sort_by(f64::total_cmp);
            for pair in crossings.chunks_exact(2) {
                let first = ((pair[0] - self.origin.x) / self.cell - 0.5)
                    .ceil()
                    .max(0.0) as usize;
                let last = ((pair[1] - self.origin.x) / self.cell - 0.5).floor();
                if last < 0.0 {
                    continue;
                }
                let last = (last as usize).min(self.cols - 1);
                for col in first..=last {
                    self.free[row * self.cols + col] = true;
                }
            }
        }
    }

    /// Dijkstra from the joins' cells over free cells.
    fn spread(&mut self, joins: &[Join]) {
        let mut queue = BinaryHeap::new();
        for join in joins {
            if let Some(i) = self.index_of(join.point)
                && join.remaining < self.cost[i]
            {
                self.free[i] = true;
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
        let (row, col) = ((index / self.cols) as isize, (index % self.cols) as isize);
        let free = move |r: isize, c: isize| {
            let inside = r >= 0 && c >= 0 && (r as usize) < self.rows && (c as usize) < self.cols;
            inside && self.free[r as usize * self.cols + c as usize]
        };
        const MOVES: [(isize, isize); 8] = [
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
            let open = free(r, c) && (!diagonal || (free(row + dr, col) && free(row, col + dc)));
            let step = if diagonal {
                self.cell * std::f64::consts::SQRT_2
            } else {
                self.cell
            };
            open.then(|| (r as usize * self.cols + c as usize, step))
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
