//! Shared test fixtures: synthetic areas and the real areas as [`Area`]s.

use crate::geometry::{Area, Point, Polygon};
use crate::test_areas::{REAL_AREAS, RealArea};

/// An area to test in, with a start route that leaves the car inside it.
#[derive(Debug, Clone)]
pub struct Fixture {
    pub name: &'static str,
    pub area: Area,
    pub start_route: Vec<Point>,
}

pub fn points(raw: &[[f64; 2]]) -> Vec<Point> {
    raw.iter().map(|&p| Point::from(p)).collect()
}

pub fn polygon(raw: &[[f64; 2]]) -> Polygon {
    Polygon::new(points(raw)).unwrap()
}

pub fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon {
    polygon(&[[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
}

pub fn real(area: &RealArea) -> Fixture {
    let cutouts = area.cutouts.iter().map(|c| polygon(c)).collect();
    Fixture {
        name: area.name,
        area: Area::new(polygon(area.fence), cutouts).unwrap(),
        start_route: points(area.start_route),
    }
}

pub fn real_areas() -> Vec<Fixture> {
    REAL_AREAS.iter().map(real).collect()
}

/// A 20 m square with two square cutouts.
pub fn square_with_cutouts() -> Fixture {
    Fixture {
        name: "square with cutouts",
        area: Area::new(
            rect(0., 0., 20., 20.),
            vec![rect(5., 5., 8., 8.), rect(12., 11., 15., 16.)],
        )
        .unwrap(),
        start_route: points(&[[2., 2.], [3., 2.5]]),
    }
}

/// An L-shaped area with 6 m wide arms.
pub fn l_shape() -> Fixture {
    Fixture {
        name: "L-shape",
        area: Area::new(
            polygon(&[
                [0., 0.],
                [20., 0.],
                [20., 6.],
                [6., 6.],
                [6., 20.],
                [0., 20.],
            ]),
            vec![],
        )
        .unwrap(),
        start_route: points(&[[1., 3.], [2., 3.]]),
    }
}

/// A 3 m wide corridor, 40 m long, with a room at its west end: the car starts in the room.
pub fn corridor_with_room() -> Fixture {
    Fixture {
        name: "corridor with a room",
        area: Area::new(
            polygon(&[
                [0., 0.],
                [8., 0.],
                [8., 2.5],
                [48., 2.5],
                [48., 5.5],
                [8., 5.5],
                [8., 8.],
                [0., 8.],
            ]),
            vec![],
        )
        .unwrap(),
        start_route: points(&[[2., 4.], [3., 4.]]),
    }
}

/// A 1.5 m wide, 40 m long corridor where the car cannot turn.
pub fn narrow_corridor() -> Area {
    Area::new(rect(0., 0., 40., 1.5), vec![]).unwrap()
}

pub fn synthetic_areas() -> Vec<Fixture> {
    vec![square_with_cutouts(), l_shape(), corridor_with_room()]
}

pub fn all_areas() -> Vec<Fixture> {
    let mut all = synthetic_areas();
    all.extend(real_areas());
    all
}
