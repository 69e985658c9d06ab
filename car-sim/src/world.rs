//! The physical world around the car: UWB anchors where they really are, obstacles that block line
//! of sight and walls that reflect, and the radio path between the car's antenna and an anchor.

use scenarios::geometry::{BBox, Point, Polygon, segments_intersect};

/// A UWB anchor as it physically stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldAnchor {
    /// The UWB id the module answers to.
    pub id: u8,
    /// Position in the local ENU plane, m.
    pub position: Point,
    /// Height of the antenna above ground, m.
    pub height: f64,
    /// Its range bias (antenna-delay calibration error), m, when known (a car profile's
    /// `range_bias_m`); `None` draws it from the radio model ([`crate::RadioModel::anchor_bias_m`]).
    pub range_bias_m: Option<f64>,
}

/// A straight reflecting surface seen from above.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// One end.
    pub a: Point,
    /// The other end.
    pub b: Point,
}

/// The world the simulated car drives in.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct World {
    /// The anchors as they physically stand (they answer range requests).
    pub anchors: Vec<WorldAnchor>,
    /// Footprints that block line of sight.
    pub obstacles: Vec<Polygon>,
    /// Surfaces that reflect.
    pub walls: Vec<Wall>,
}

/// How the radio signal travels between the car and an anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RadioPath {
    /// Line of sight: the direct path, `length` m in the plane.
    LineOfSight {
        /// Planar path length, m.
        length: f64,
    },
    /// The direct path is blocked; the shortest unblocked single reflection via wall `wall`.
    Reflected {
        /// Index of the wall in [`World::walls`].
        wall: usize,
        /// Planar length of the reflected path, m.
        length: f64,
        /// Planar length of the blocked direct path, m.
        direct: f64,
    },
    /// Blocked, and no wall offers an unblocked reflection: the exchange fails.
    Blocked,
}

impl RadioPath {
    /// The planar length travelled, if the signal arrives.
    pub fn length(&self) -> Option<f64> {
        match *self {
            Self::LineOfSight { length } | Self::Reflected { length, .. } => Some(length),
            Self::Blocked => None,
        }
    }
}

impl World {
    /// The world of a scenario: its anchors (where they physically stand), its obstacles and its
    /// walls (illustrative ones included: the simulator models them as drawn).
    pub fn from_scenario(scenario: &scenarios::Scenario) -> Self {
        Self {
            anchors: scenario
                .anchors
                .iter()
                .map(|a| WorldAnchor {
                    id: a.id,
                    position: a.position(),
                    height: a.height,
                    range_bias_m: None,
                })
                .collect(),
            obstacles: scenario
                .environment
                .obstacles
                .iter()
                .map(|o| o.polygon.clone())
                .collect(),
            walls: scenario
                .environment
                .walls
                .iter()
                .map(|w| Wall { a: w.a, b: w.b })
                .collect(),
        }
    }

    /// The physical anchor answering to `id`.
    pub fn anchor(&self, id: u8) -> Option<&WorldAnchor> {
        self.anchors.iter().find(|a| a.id == id)
    }

    /// Whether an obstacle cuts the straight path `a–b`.
    pub fn is_blocked(&self, a: Point, b: Point) -> bool {
        let Some(bbox) = BBox::around([a, b]) else {
            return false;
        };
        self.obstacles
            .iter()
            .filter(|o| o.bbox().overlaps(&bbox))
            .any(|o| o.edges().any(|(c, d)| segments_intersect(a, b, c, d)))
    }

    /// The radio path between the car's antenna and an anchor at `anchor`.
    pub fn radio_path(&self, antenna: Point, anchor: Point) -> RadioPath {
        let direct = antenna.dist(anchor);
        if !self.is_blocked(antenna, anchor) {
            return RadioPath::LineOfSight { length: direct };
        }
        self.walls
            .iter()
            .enumerate()
            .filter_map(|(i, w)| self.reflection(antenna, anchor, *w).map(|len| (i, len)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .map_or(RadioPath::Blocked, |(wall, length)| RadioPath::Reflected {
                wall,
                length,
                direct,
            })
    }

    /// Length of the mirror-image path antenna → wall → anchor, if the reflection point lies on
    /// the wall and neither leg is blocked.
    fn reflection(&self, antenna: Point, anchor: Point, wall: Wall) -> Option<f64> {
        let image = mirror(anchor, wall)?;
        let hit = segment_intersection(antenna, image, wall.a, wall.b)?;
        if self.is_blocked(antenna, hit) || self.is_blocked(hit, anchor) {
            return None;
        }
        Some(antenna.dist(image))
    }
}

/// The mirror image of `p` across the line through the wall (`None` for a zero-length wall).
fn mirror(p: Point, wall: Wall) -> Option<Point> {
    let d = wall.b - wall.a;
    let len2 = d.dot(d);
    if len2 <= 1e-12 {
        return None;
    }
    let t = (p - wall.a).dot(d) / len2;
    let foot = wall.a + d * t;
    Some(foot * 2.0 - p)
}

/// The crossing point of segments `p–q` and `a–b` when they cross (not parallel).
fn segment_intersection(p: Point, q: Point, a: Point, b: Point) -> Option<Point> {
    let r = q - p;
    let s = b - a;
    let denom = r.cross(s);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = (a - p).cross(s) / denom;
    let u = (a - p).cross(r) / denom;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then(|| p + r * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(cx: f64, cy: f64, half: f64) -> Polygon {
        Polygon::new(vec![
            Point::new(cx - half, cy - half),
            Point::new(cx + half, cy - half),
            Point::new(cx + half, cy + half),
            Point::new(cx - half, cy + half),
        ])
        .expect("a square")
    }

    #[test]
    fn open_world_is_line_of_sight() {
        let w = World::default();
        let p = w.radio_path(Point::new(0.0, 0.0), Point::new(3.0, 4.0));
        assert_eq!(p, RadioPath::LineOfSight { length: 5.0 });
    }

    #[test]
    fn an_obstacle_without_a_wall_blocks() {
        let w = World {
            obstacles: vec![square(5.0, 0.0, 1.0)],
            ..World::default()
        };
        assert_eq!(
            w.radio_path(Point::new(0.0, 0.0), Point::new(10.0, 0.0)),
            RadioPath::Blocked
        );
    }

    #[test]
    fn a_wall_behind_offers_the_mirror_image_path() {
        // Car at (0,0), anchor at (10,0), rock between, wall along y = 5.
        let w = World {
            obstacles: vec![square(5.0, 0.0, 1.0)],
            walls: vec![Wall {
                a: Point::new(-20.0, 5.0),
                b: Point::new(20.0, 5.0),
            }],
            ..World::default()
        };
        let path = w.radio_path(Point::new(0.0, 0.0), Point::new(10.0, 0.0));
        let expected = (10.0f64.powi(2) + 10.0f64.powi(2)).sqrt();
        match path {
            RadioPath::Reflected {
                wall,
                length,
                direct,
            } => {
                assert_eq!(wall, 0);
                assert!((length - expected).abs() < 1e-9);
                assert_eq!(direct, 10.0);
            }
            other => panic!("expected a reflection, got {other:?}"),
        }
    }

    #[test]
    fn a_reflection_whose_leg_is_blocked_does_not_count() {
        let w = World {
            obstacles: vec![square(5.0, 0.0, 1.0), square(2.5, 2.5, 0.5)],
            walls: vec![Wall {
                a: Point::new(-20.0, 5.0),
                b: Point::new(20.0, 5.0),
            }],
            ..World::default()
        };
        assert_eq!(
            w.radio_path(Point::new(0.0, 0.0), Point::new(10.0, 0.0)),
            RadioPath::Blocked
        );
    }

    #[test]
    fn a_wall_too_short_to_reach_the_reflection_point_does_not_count() {
        let w = World {
            obstacles: vec![square(5.0, 0.0, 1.0)],
            walls: vec![Wall {
                a: Point::new(12.0, 5.0),
                b: Point::new(20.0, 5.0),
            }],
            ..World::default()
        };
        assert_eq!(
            w.radio_path(Point::new(0.0, 0.0), Point::new(10.0, 0.0)),
            RadioPath::Blocked
        );
    }
}
