//! Pictures of an area as SVG: fence, cutouts, routes, anchors, environment, a trajectory sample,
//! the coverage heat map and the hot spots of a validation.

use std::fmt::Write;

use scenarios::Scenario;
use trajgen::{BBox, Point, ValidationReport};

/// Width of the drawing, pixels.
const WIDTH_PX: f64 = 1000.0;
/// Blank border around the area, metres.
const BORDER_M: f64 = 2.0;

/// Maps ENU metres to SVG pixels (north up).
struct Frame {
    bbox: BBox,
    scale: f64,
}

impl Frame {
    fn new(bbox: BBox) -> Self {
        let (w, _) = bbox.size();
        Self {
            bbox,
            scale: WIDTH_PX / (w + 2.0 * BORDER_M),
        }
    }

    fn x(&self, x: f64) -> f64 {
        (x - self.bbox.min.x + BORDER_M) * self.scale
    }

    fn y(&self, y: f64) -> f64 {
        (self.bbox.max.y - y + BORDER_M) * self.scale
    }

    fn height_px(&self) -> f64 {
        (self.bbox.size().1 + 2.0 * BORDER_M) * self.scale
    }

    fn points(&self, points: &[Point]) -> String {
        points
            .iter()
            .map(|p| format!("{:.1},{:.1}", self.x(p.x), self.y(p.y)))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// What the picture must hold: the area, and the anchors, obstacles and walls, which may lie
/// outside the fence.
fn picture_bbox(scenario: &Scenario) -> BBox {
    let anchors = scenario.anchors.iter().map(|a| Point::new(a.x, a.y));
    let environment = &scenario.environment;
    let obstacles = environment
        .obstacles
        .iter()
        .flat_map(|o| o.polygon.vertices().iter().copied());
    let walls = environment.walls.iter().flat_map(|w| [w.a, w.b]);
    anchors
        .chain(obstacles)
        .chain(walls)
        .fold(scenario.area.bbox(), BBox::including)
}

/// The start of a picture of `frame` with room for two lines of legend: the `<svg>` element and
/// a white background.
fn open_svg(frame: &Frame) -> String {
    let mut svg = String::new();
    let legend_px = 60.0;
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.0} {h:.0}" font-family="sans-serif" font-size="13">"#,
        w = WIDTH_PX,
        h = frame.height_px() + legend_px
    );
    let _ = writeln!(
        svg,
        r##"<rect width="100%" height="100%" fill="#ffffff"/>"##
    );
    svg
}

/// The validation picture: the area, the coverage heat map, a sample of the trajectory and the
/// numbered hot spots.
pub fn area_picture(scenario: &Scenario, report: &ValidationReport) -> String {
    let frame = Frame::new(picture_bbox(scenario));
    let mut svg = open_svg(&frame);
    heat_map(&mut svg, &frame, report);
    area_outline(&mut svg, &frame, scenario);
    let _ = writeln!(
        svg,
        r##"<polyline points="{}" fill="none" stroke="#1f4e9c" stroke-width="0.6" stroke-opacity="0.5"/>"##,
        frame.points(&report.trajectory_sample)
    );
    routes_and_anchors(&mut svg, &frame, scenario);
    hot_spots(&mut svg, &frame, report);
    let _ = writeln!(
        svg,
        r##"<text x="10" y="{:.0}">{}: {} — {:.2} km, {} failure(s), max outer tries {} of {}, coverage {:.1} %</text>"##,
        frame.height_px() + 22.0,
        xml_escape(&scenario.name),
        report.verdict,
        report.km,
        report.failures,
        report.max_outer_tries,
        report.outer_tries_limit,
        report.coverage * 100.0
    );
    let _ = writeln!(
        svg,
        r##"<text x="10" y="{:.0}" fill="#555">heat: visits per 0.5 m cell (pale = rarely, dark = often, grey = never); blue: trajectory sample; red: hot spots, worst first</text>"##,
        frame.height_px() + 44.0
    );
    svg.push_str("</svg>\n");
    svg
}

/// Where a campaign's UWB estimate was off: the area with its environment, every test's driven
/// track (RTK positions) in grey, and each state sample whose deviation exceeds `threshold_m` as a
/// red dot; `caption` under it.
pub fn deviation_picture(
    scenario: &Scenario,
    tracks: &[Vec<(Point, Option<f64>)>],
    threshold_m: f64,
    caption: &str,
) -> String {
    let frame = Frame::new(picture_bbox(scenario));
    let mut svg = open_svg(&frame);
    area_outline(&mut svg, &frame, scenario);
    for track in tracks {
        let points: Vec<Point> = track.iter().map(|(p, _)| *p).collect();
        let _ = writeln!(
            svg,
            r##"<polyline points="{}" fill="none" stroke="#888" stroke-width="0.6" stroke-opacity="0.6"/>"##,
            frame.points(&points)
        );
    }
    let (mut samples, mut over) = (0usize, 0usize);
    for (p, deviation) in tracks.iter().flatten() {
        samples += 1;
        if deviation.is_some_and(|d| d > threshold_m) {
            over += 1;
            let _ = writeln!(
                svg,
                r##"<circle cx="{:.1}" cy="{:.1}" r="2.2" fill="#d7191c" fill-opacity="0.7"/>"##,
                frame.x(p.x),
                frame.y(p.y)
            );
        }
    }
    routes_and_anchors(&mut svg, &frame, scenario);
    let _ = writeln!(
        svg,
        r##"<text x="10" y="{:.0}">{}</text>"##,
        frame.height_px() + 22.0,
        xml_escape(caption)
    );
    let _ = writeln!(
        svg,
        r##"<text x="10" y="{:.0}" fill="#555">grey: {} tests driven (RTK); red: {over} of {samples} state samples with UWB more than {threshold_m:.1} m from RTK; brown: obstacle; purple line: reflecting wall</text>"##,
        frame.height_px() + 44.0,
        tracks.len()
    );
    svg.push_str("</svg>\n");
    svg
}

fn heat_map(svg: &mut String, frame: &Frame, report: &ValidationReport) {
    let (grid, visits) = (&report.grid.raster, &report.grid.visits);
    let max_visits = visits.iter().copied().max().unwrap_or(0).max(1);
    let size = grid.cell_size * frame.scale;
    for row in 0..grid.rows {
        for col in 0..grid.cols {
            let i = row * grid.cols + col;
            if !grid.drivable[i] {
                continue;
            }
            let centre = grid.cell_centre(col, row);
            let fill = heat_colour(visits[i], max_visits);
            let _ = writeln!(
                svg,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.2}" height="{:.2}" fill="{fill}"/>"#,
                frame.x(centre.x) - size / 2.0,
                frame.y(centre.y) - size / 2.0,
                size,
                size
            );
        }
    }
}

/// Never visited: grey; otherwise from pale yellow to dark orange on a log scale.
fn heat_colour(visits: u32, max_visits: u32) -> String {
    if visits == 0 {
        return "#d9d9d9".to_owned();
    }
    let t = (f64::from(visits).ln_1p() / f64::from(max_visits).ln_1p()).clamp(0.0, 1.0);
    let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
    format!(
        "#{:02x}{:02x}{:02x}",
        lerp(255.0, 204.0),
        lerp(247.0, 76.0),
        lerp(188.0, 2.0)
    )
}

fn area_outline(svg: &mut String, frame: &Frame, scenario: &Scenario) {
    let _ = writeln!(
        svg,
        r##"<polygon points="{}" fill="none" stroke="#000" stroke-width="2"/>"##,
        frame.points(scenario.area.fence().vertices())
    );
    for cutout in scenario.area.cutouts() {
        let _ = writeln!(
            svg,
            r##"<polygon points="{}" fill="#555" stroke="#000" stroke-width="1.5"/>"##,
            frame.points(cutout.vertices())
        );
    }
    for obstacle in &scenario.environment.obstacles {
        let _ = writeln!(
            svg,
            r##"<polygon points="{}" fill="#8b5a2b" fill-opacity="0.8"><title>{}</title></polygon>"##,
            frame.points(obstacle.polygon.vertices()),
            xml_escape(&obstacle.name)
        );
    }
    for wall in &scenario.environment.walls {
        let _ = writeln!(
            svg,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#6a3d9a" stroke-width="4"><title>{}</title></line>"##,
            frame.x(wall.a.x),
            frame.y(wall.a.y),
            frame.x(wall.b.x),
            frame.y(wall.b.y),
            xml_escape(&wall.name)
        );
    }
}

fn routes_and_anchors(svg: &mut String, frame: &Frame, scenario: &Scenario) {
    for (route, colour) in [
        (&scenario.recovery_route, "#e66101"),
        (&scenario.start_route, "#1a9641"),
    ] {
        let _ = writeln!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="3"/>"#,
            frame.points(&route.positions())
        );
    }
    for anchor in &scenario.anchors {
        let (x, y) = (frame.x(anchor.x), frame.y(anchor.y));
        let _ = writeln!(
            svg,
            r##"<path d="M{:.1},{:.1} l7,12 l-14,0 z" fill="#7b3294"/><text x="{:.1}" y="{:.1}" fill="#7b3294">anchor {}</text>"##,
            x,
            y - 8.0,
            x + 9.0,
            y + 4.0,
            anchor.id
        );
    }
}

fn hot_spots(svg: &mut String, frame: &Frame, report: &ValidationReport) {
    for (rank, spot) in report.hotspots.iter().enumerate() {
        let (x, y) = (frame.x(spot.x), frame.y(spot.y));
        let _ = writeln!(
            svg,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="10" fill="none" stroke="#d7191c" stroke-width="2.5"/><text x="{:.1}" y="{:.1}" fill="#d7191c" font-weight="bold">{} ({} tries)</text>"##,
            x + 12.0,
            y - 8.0,
            rank + 1,
            spot.outer_tries
        );
    }
}

fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_picture_holds_anchors_and_environment_outside_the_fence() {
        let scenario = scenarios::bundled::load("parking-lot-rock")
            .unwrap()
            .scenario;
        let fence = scenario.area.bbox();
        let wall = &scenario.environment.walls[0];
        let anchors = scenario.anchors.iter().map(|a| Point::new(a.x, a.y));
        let outside: Vec<Point> = anchors
            .chain([wall.a, wall.b])
            .filter(|&p| !fence.contains(p))
            .collect();
        assert!(
            !outside.is_empty(),
            "the rock lot's wall or anchors lie outside the fence"
        );
        let picture = picture_bbox(&scenario);
        assert!(outside.iter().all(|&p| picture.contains(p)), "{outside:?}");
    }
}
