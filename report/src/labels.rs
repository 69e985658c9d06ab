//! Labels that do not overlap, on the report's maps and plots: each label is offered places in
//! its order of preference (rings around its marker on a map, rows under the top of a plot) and
//! takes the first whose box meets no label placed before it and no obstacle and lies inside the
//! picture. A label without a free place takes its least crowded one (it never happens with the
//! rings and rows below and a few dozen labels, see the tests). All in pixels, y down.

/// A box in pixels (x to the right, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Left.
    pub x0: f64,
    /// Top.
    pub y0: f64,
    /// Right.
    pub x1: f64,
    /// Bottom.
    pub y1: f64,
}

impl Rect {
    /// The box of width `w` and height `h` with its top left corner at (`x`, `y`).
    pub fn at(x: f64, y: f64, w: f64, h: f64) -> Self {
        Self {
            x0: x,
            y0: y,
            x1: x + w,
            y1: y + h,
        }
    }

    /// The square of side `2 r` centred on (`x`, `y`).
    pub fn around(x: f64, y: f64, r: f64) -> Self {
        Self::at(x - r, y - r, 2.0 * r, 2.0 * r)
    }

    /// True when the boxes share more than an edge.
    pub fn intersects(&self, other: &Self) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }

    /// The area the boxes share.
    fn overlap(&self, other: &Self) -> f64 {
        let w = self.x1.min(other.x1) - self.x0.max(other.x0);
        let h = self.y1.min(other.y1) - self.y0.max(other.y0);
        w.max(0.0) * h.max(0.0)
    }

    /// True when the box lies wholly inside `bounds`.
    fn inside(&self, bounds: &Self) -> bool {
        self.x0 >= bounds.x0 && self.y0 >= bounds.y0 && self.x1 <= bounds.x1 && self.y1 <= bounds.y1
    }

    /// The box moved the least to lie inside `bounds` (its top left inside when it is larger).
    fn moved_into(&self, bounds: &Self) -> Self {
        let shift = |lo: f64, hi: f64, min: f64, max: f64| {
            if lo < min {
                min - lo
            } else if hi > max {
                (max - hi).max(min - lo)
            } else {
                0.0
            }
        };
        let dx = shift(self.x0, self.x1, bounds.x0, bounds.x1);
        let dy = shift(self.y0, self.y1, bounds.y0, bounds.y1);
        Self::at(self.x0 + dx, self.y0 + dy, self.width(), self.height())
    }

    /// Its centre.
    pub fn centre(&self) -> (f64, f64) {
        ((self.x0 + self.x1) / 2.0, (self.y0 + self.y1) / 2.0)
    }

    /// The point of the box nearest to (`x`, `y`).
    pub fn nearest(&self, x: f64, y: f64) -> (f64, f64) {
        (x.clamp(self.x0, self.x1), y.clamp(self.y0, self.y1))
    }

    fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    fn height(&self) -> f64 {
        self.y1 - self.y0
    }
}

/// The size in pixels of `text` in a sans-serif font of `px` pixels, with a small padding: wide
/// enough for digits and lower-case letters (about 0.6 em each).
pub fn text_size(text: &str, px: f64) -> (f64, f64) {
    let chars = text.chars().count() as f64;
    (chars * px * 0.62 + 6.0, px + 4.0)
}

/// Gap between a marker and its first ring of places, pixels.
const RING_GAP: f64 = 10.0;
/// How many rings of places around a marker.
const RINGS: usize = 7;

/// Places for a label of `size` next to the marker at (`x`, `y`): eight around it (right, above,
/// left, below, then the corners) on each of [`RINGS`] rings, nearest first.
pub fn around(x: f64, y: f64, size: (f64, f64)) -> Vec<Rect> {
    let (w, h) = size;
    let directions = [
        (1.0, 0.0),
        (0.0, -1.0),
        (-1.0, 0.0),
        (0.0, 1.0),
        (1.0, -1.0),
        (-1.0, -1.0),
        (-1.0, 1.0),
        (1.0, 1.0),
    ];
    (1..=RINGS)
        .flat_map(|ring| {
            // Rings a label's size apart, so places of one direction never overlap.
            let r = RING_GAP + (ring - 1) as f64 * (w.max(h) + 2.0);
            directions.into_iter().map(move |(dx, dy): (f64, f64)| {
                // The box's side facing the marker is r away from it.
                let cx = x + dx * (r + w / 2.0);
                let cy = y + dy * (r + h / 2.0);
                Rect::at(cx - w / 2.0, cy - h / 2.0, w, h)
            })
        })
        .collect()
}

/// Places for a label of `size` in a plot whose drawing area starts at `top`: at `x` in the
/// rows from the top down to `bottom`, then the same rows a label's width further right each
/// time (up to four widths).
pub fn rows(x: f64, top: f64, bottom: f64, size: (f64, f64)) -> Vec<Rect> {
    let (w, h) = size;
    let rows = (((bottom - top) / h).floor() as usize).max(1);
    (0..5)
        .flat_map(|shift| {
            (0..rows).map(move |row| Rect::at(x + shift as f64 * w, top + row as f64 * h, w, h))
        })
        .collect()
}

/// One place for each label: label k takes the first of `candidates[k]` (each moved inside
/// `bounds` where it sticks out) that meets neither an obstacle nor a label placed before it,
/// else the candidate that overlaps them least (a label without candidates gets an empty box at
/// the origin).
pub fn place(candidates: &[Vec<Rect>], obstacles: &[Rect], bounds: Rect) -> Vec<Rect> {
    let mut placed: Vec<Rect> = Vec::with_capacity(candidates.len());
    for options in candidates {
        let options: Vec<Rect> = options.iter().map(|r| r.moved_into(&bounds)).collect();
        let taken = |r: &Rect| placed.iter().chain(obstacles).any(|o| r.intersects(o));
        let free = options.iter().find(|r| r.inside(&bounds) && !taken(r));
        let chosen = free
            .copied()
            .or_else(|| least_crowded(&options, &placed, obstacles, bounds));
        placed.push(chosen.unwrap_or(Rect::at(0.0, 0.0, 0.0, 0.0)));
    }
    placed
}

/// The candidate that overlaps the boxes placed and the obstacles least, a box outside the
/// bounds counting its area outside as overlap.
fn least_crowded(
    options: &[Rect],
    placed: &[Rect],
    obstacles: &[Rect],
    bounds: Rect,
) -> Option<Rect> {
    let crowding = |r: &Rect| {
        let outside = r.width() * r.height() - r.overlap(&bounds);
        outside
            + placed
                .iter()
                .chain(obstacles)
                .map(|o| r.overlap(o))
                .sum::<f64>()
    };
    options
        .iter()
        .copied()
        .min_by(|a, b| crowding(a).total_cmp(&crowding(b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_disjoint(boxes: &[Rect]) {
        for (i, a) in boxes.iter().enumerate() {
            for b in &boxes[i + 1..] {
                assert!(!a.intersects(b), "{a:?} and {b:?} overlap");
            }
        }
    }

    #[test]
    fn boxes_meet_only_when_they_share_more_than_an_edge() {
        let a = Rect::at(0.0, 0.0, 10.0, 10.0);
        assert!(a.intersects(&Rect::at(9.0, 9.0, 5.0, 5.0)));
        assert!(!a.intersects(&Rect::at(10.0, 0.0, 5.0, 5.0)));
        assert!(!a.intersects(&Rect::at(0.0, 11.0, 5.0, 5.0)));
        assert_eq!(a.nearest(20.0, 5.0), (10.0, 5.0));
    }

    #[test]
    fn a_crowd_of_markers_gets_labels_that_do_not_overlap() {
        // Twenty faults added within a few pixels of each other (a car standing still), their
        // markers as obstacles, in a map of 800 × 500 pixels.
        let markers: Vec<(f64, f64)> = (0..20)
            .map(|k| (400.0 + f64::from(k % 5), 250.0 + f64::from(k / 5)))
            .collect();
        let obstacles: Vec<Rect> = markers
            .iter()
            .map(|&(x, y)| Rect::around(x, y, 7.0))
            .collect();
        let candidates: Vec<Vec<Rect>> = markers
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| around(x, y, text_size(&(k + 1).to_string(), 12.0)))
            .collect();
        let bounds = Rect::at(0.0, 0.0, 800.0, 500.0);
        let placed = place(&candidates, &obstacles, bounds);
        assert_eq!(placed.len(), 20);
        assert_disjoint(&placed);
        for p in &placed {
            assert!(p.inside(&bounds), "{p:?}");
            assert!(
                obstacles.iter().all(|o| !p.intersects(o)),
                "{p:?} covers a marker"
            );
        }
    }

    #[test]
    fn a_crowd_in_a_corner_stays_inside_the_picture() {
        let candidates: Vec<Vec<Rect>> = (0..12)
            .map(|k| around(2.0, 2.0, text_size(&format!("{k}"), 12.0)))
            .collect();
        let bounds = Rect::at(0.0, 0.0, 300.0, 200.0);
        let placed = place(&candidates, &[], bounds);
        assert_disjoint(&placed);
        assert!(placed.iter().all(|p| p.inside(&bounds)), "{placed:?}");
    }

    #[test]
    fn overlapping_windows_get_labels_in_rows_that_do_not_overlap() {
        // Fifteen fault windows starting within 30 pixels of each other in a plot 200 pixels
        // high, and segment labels at the same places.
        let candidates: Vec<Vec<Rect>> = (0..15)
            .map(|k| {
                let label = format!("{}", k + 1);
                rows(
                    100.0 + f64::from(k) * 2.0,
                    12.0,
                    212.0,
                    text_size(&label, 12.0),
                )
            })
            .chain((0..6).map(|k| rows(105.0 + f64::from(k), 12.0, 212.0, text_size("s10", 12.0))))
            .collect();
        let placed = place(&candidates, &[], Rect::at(60.0, 12.0, 800.0, 200.0));
        assert_eq!(placed.len(), 21);
        assert_disjoint(&placed);
    }

    #[test]
    fn a_label_takes_its_first_free_place() {
        let first = Rect::at(10.0, 10.0, 5.0, 5.0);
        let second = Rect::at(20.0, 10.0, 5.0, 5.0);
        let bounds = Rect::at(0.0, 0.0, 100.0, 100.0);
        assert_eq!(place(&[vec![first, second]], &[], bounds), [first]);
        assert_eq!(place(&[vec![first, second]], &[first], bounds), [second]);
        // Nothing free: the least crowded.
        let half = Rect::at(12.0, 10.0, 5.0, 5.0);
        assert_eq!(place(&[vec![first, half]], &[first], bounds), [half]);
    }
}
