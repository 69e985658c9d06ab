//! The report's pictures as SVG, drawn with `plotters`' SVG backend: a map of the area with the
//! planned route, the RTK and UWB tracks and the faults' places, and a plot of the deviation
//! against time with the threshold, the segments and the faults' windows.
//!
//! Points outside a chart's ranges are left out (a faulted UWB estimate can be far away) rather
//! than drawn over the axes; tracks are decimated to [`MAX_TRACK_POINTS`] beforehand.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use scenarios::Scenario;
use trajgen::{BBox, Point};

use super::ReportError;
use super::data::Sample;
use super::labels::{Rect, around, place, rows, text_size};
use super::route::Boundary;

/// The most samples a track is drawn with (see [`decimate`]).
pub const MAX_TRACK_POINTS: usize = 2000;

/// Green: below half the threshold.
pub const GREEN: RGBColor = RGBColor(0x1a, 0x98, 0x50);
/// Amber: up to the threshold.
pub const AMBER: RGBColor = RGBColor(0xe6, 0x8a, 0x00);
/// Red: above the threshold.
pub const RED_ABOVE: RGBColor = RGBColor(0xd7, 0x19, 0x1c);
/// The faults' places and windows.
pub const FAULT: RGBColor = RGBColor(0x7b, 0x32, 0x94);
/// The RTK track.
const RTK: RGBColor = RGBColor(0x25, 0x25, 0x25);
/// The planned route.
const PLANNED: RGBColor = RGBColor(0x4a, 0x7f, 0xc1);
/// Colours of the runs of a replay, in order.
pub const RUN_COLOURS: [RGBColor; 6] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0x17, 0xbe, 0xcf),
];

fn draw_error(e: impl std::fmt::Display) -> ReportError {
    ReportError::Draw(e.to_string())
}

/// `#rrggbb` of a colour, for the page's legends.
pub fn css(colour: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", colour.0, colour.1, colour.2)
}

/// The colour of a deviation against `threshold`.
pub fn class_colour(deviation: f64, threshold: f64) -> RGBColor {
    if deviation > threshold {
        RED_ABOVE
    } else if deviation >= threshold / 2.0 {
        AMBER
    } else {
        GREEN
    }
}

/// At most `max` of `samples`: when there are more, the samples are cut into buckets of equal
/// count and each bucket keeps its samples of smallest and largest deviation (in time order), so
/// peaks survive.
pub fn decimate(samples: &[Sample], max: usize) -> Vec<Sample> {
    if samples.len() <= max || max < 2 {
        return samples.to_vec();
    }
    let bucket = samples.len().div_ceil(max / 2);
    let key = |s: &Sample| s.deviation_m.unwrap_or(f64::NEG_INFINITY);
    samples
        .chunks(bucket)
        .flat_map(|chunk| {
            let lo = (0..chunk.len()).min_by(|&a, &b| key(&chunk[a]).total_cmp(&key(&chunk[b])));
            let hi = (0..chunk.len()).max_by(|&a, &b| key(&chunk[a]).total_cmp(&key(&chunk[b])));
            let mut keep: Vec<usize> = lo.into_iter().chain(hi).collect();
            keep.sort_unstable();
            keep.dedup();
            keep.into_iter().map(|i| chunk[i]).collect::<Vec<_>>()
        })
        .collect()
}

/// How a track's UWB positions are coloured.
#[derive(Debug, Clone, Copy)]
pub enum Colouring {
    /// By deviation against the threshold (green, amber, red).
    ByDeviation {
        /// The oracle's threshold, metres.
        threshold: f64,
    },
    /// In one colour (a run of a replay), with the samples above the threshold marked red.
    Run {
        /// The run's colour.
        colour: RGBColor,
        /// The oracle's threshold, metres.
        threshold: f64,
    },
}

/// A test's (or run's) track on the map.
#[derive(Debug, Clone)]
pub struct TrackLayer<'a> {
    /// Its samples (decimated).
    pub samples: &'a [Sample],
    /// How the UWB track is coloured.
    pub colouring: Colouring,
    /// Whether to draw the RTK track.
    pub rtk: bool,
}

/// A fault on the map: where the car was when it was added, and where the car drove while it
/// acted.
#[derive(Debug, Clone)]
pub struct FaultMark {
    /// The place.
    pub at: Point,
    /// Its label: its number in the key below the map (empty: unlabelled).
    pub label: String,
    /// The RTK track during its window.
    pub window: Vec<Point>,
}

/// What a map shows.
#[derive(Debug, Clone, Default)]
pub struct MapLayers<'a> {
    /// The planned route: the segments' points, each segment from the end of the one before.
    pub segments: Vec<Vec<Point>>,
    /// How many of them were driven (the rest are drawn faintly, unlabelled).
    pub driven: usize,
    /// The tracks.
    pub tracks: Vec<TrackLayer<'a>>,
    /// The faults.
    pub faults: Vec<FaultMark>,
    /// A heat map of the cells driven (the campaign's coverage), drawn under the routes.
    pub heat: Option<&'a trajgen::validation::CoverageGrid>,
}

/// The picture's pixel size and its ranges in metres, with one scale on both axes.
struct MapFrame {
    width: u32,
    height: u32,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
}

const MAP_WIDTH: u32 = 860;
const MARGIN: u32 = 12;
const Y_LABELS: u32 = 76;
const X_LABELS: u32 = 48;
/// Font size of the axes' tick labels and descriptions, pixels as shown (the pictures are shown
/// at their own size on a wide page, smaller only on a narrow screen).
const AXIS_PX: f64 = 14.0;
/// Font size of the labels in a picture, pixels as shown.
const LABEL_PX: f64 = 12.5;
/// `plotters`' SVG backend writes a font of size `s` as `font-size` `s / 1.24`: a size given to
/// it is the size shown times this.
const SVG_FONT: f64 = 1.24;

/// A sans-serif font shown `px` pixels high.
fn sans(px: f64) -> (&'static str, f64) {
    ("sans-serif", px * SVG_FONT)
}
/// Radius of a fault's marker on the map, pixels.
const MARKER_PX: i32 = 6;

impl MapFrame {
    fn new(bbox: BBox) -> Self {
        let (w_m, h_m) = bbox.size();
        let (w_m, h_m) = (w_m.max(1.0), h_m.max(1.0));
        let plot_w = f64::from(MAP_WIDTH - 2 * MARGIN - Y_LABELS);
        let plot_h = (plot_w * h_m / w_m).clamp(260.0, 700.0);
        let scale = (w_m / plot_w).max(h_m / plot_h);
        let (cx, cy) = (
            (bbox.min.x + bbox.max.x) / 2.0,
            (bbox.min.y + bbox.max.y) / 2.0,
        );
        let (half_w, half_h) = (scale * plot_w / 2.0, scale * plot_h / 2.0);
        Self {
            width: MAP_WIDTH,
            height: plot_h.round() as u32 + 2 * MARGIN + X_LABELS,
            x: cx - half_w..cx + half_w,
            y: cy - half_h..cy + half_h,
        }
    }

    fn contains(&self, p: Point) -> bool {
        p.is_finite() && self.x.contains(&p.x) && self.y.contains(&p.y)
    }
}

/// What the map must hold: the area and the anchors (with a border), or without a scenario the
/// planned route and the RTK tracks.
fn map_bbox(scenario: Option<&Scenario>, layers: &MapLayers<'_>) -> Option<BBox> {
    let bbox = match scenario {
        Some(s) => {
            let anchors = s.anchors.iter().map(|a| Point::new(a.x, a.y));
            Some(anchors.fold(s.area.bbox(), BBox::including))
        }
        None => {
            let route = layers.segments.iter().flatten().copied();
            let tracks = layers
                .tracks
                .iter()
                .flat_map(|t| t.samples.iter().map(|s| s.rtk));
            BBox::around(route.chain(tracks).filter(|p| p.is_finite()))
        }
    }?;
    let border = 1.5;
    Some(BBox {
        min: Point::new(bbox.min.x - border, bbox.min.y - border),
        max: Point::new(bbox.max.x + border, bbox.max.y + border),
    })
}

/// Splits `points` into runs of points inside the frame (a point outside breaks the line).
fn inside_runs(frame: &MapFrame, points: impl IntoIterator<Item = Point>) -> Vec<Vec<(f64, f64)>> {
    let mut runs = vec![Vec::new()];
    for p in points {
        if frame.contains(p) {
            if let Some(run) = runs.last_mut() {
                run.push((p.x, p.y));
            }
        } else if runs.last().is_some_and(|r| !r.is_empty()) {
            runs.push(Vec::new());
        }
    }
    runs.retain(|r| !r.is_empty());
    runs
}

/// Runs of consecutive samples of one colour (each run starts at the last point of the one
/// before, so the line is continuous). Samples without a finite UWB position break the line.
fn coloured_runs(
    samples: &[Sample],
    colour_of: impl Fn(&Sample) -> RGBColor,
    point_of: impl Fn(&Sample) -> Option<Point>,
) -> Vec<(RGBColor, Vec<Point>)> {
    let mut runs: Vec<(RGBColor, Vec<Point>)> = Vec::new();
    let mut last: Option<Point> = None;
    for s in samples {
        let Some(p) = point_of(s).filter(|p| p.is_finite()) else {
            last = None;
            continue;
        };
        let colour = colour_of(s);
        match runs.last_mut() {
            Some((c, points)) if *c == colour && last.is_some() => points.push(p),
            _ => runs.push((colour, last.into_iter().chain([p]).collect())),
        }
        last = Some(p);
    }
    runs
}

/// A heat-map colour for `visits` of at most `most`: pale yellow for one visit to dark red, on a
/// logarithmic scale (a few cells are driven far more often than the rest).
fn heat_colour(visits: u32, most: u32) -> RGBColor {
    let t = if most > 1 {
        (f64::from(visits).ln() / f64::from(most).ln()).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
    RGBColor(lerp(255.0, 165.0), lerp(237.0, 15.0), lerp(160.0, 21.0))
}

/// The map (see the module doc); `None` without anything to draw.
pub fn map_svg(
    scenario: Option<&Scenario>,
    layers: &MapLayers<'_>,
) -> Result<Option<String>, ReportError> {
    let Some(bbox) = map_bbox(scenario, layers) else {
        return Ok(None);
    };
    let frame = MapFrame::new(bbox);
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (frame.width, frame.height)).into_drawing_area();
        draw_map(&root, &frame, scenario, layers)?;
        root.present().map_err(draw_error)?;
    }
    Ok(Some(svg))
}

fn draw_map(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    frame: &MapFrame,
    scenario: Option<&Scenario>,
    layers: &MapLayers<'_>,
) -> Result<(), ReportError> {
    root.fill(&WHITE).map_err(draw_error)?;
    let mut chart = ChartBuilder::on(root)
        .margin(MARGIN)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d(frame.x.clone(), frame.y.clone())
        .map_err(draw_error)?;
    chart
        .configure_mesh()
        .light_line_style(RGBColor(0xf0, 0xf0, 0xf0))
        .bold_line_style(RGBColor(0xdd, 0xdd, 0xdd))
        .x_desc("east")
        .y_desc("north")
        .x_label_formatter(&|v| tick(*v, "m"))
        .y_label_formatter(&|v| tick(*v, "m"))
        .label_style(sans(AXIS_PX))
        .axis_desc_style(sans(AXIS_PX))
        .draw()
        .map_err(draw_error)?;
    let xy = |p: Point| (p.x, p.y);
    let closed = |points: &[Point]| -> Vec<(f64, f64)> {
        points
            .iter()
            .chain(points.first())
            .copied()
            .map(xy)
            .collect()
    };
    if let Some(s) = scenario {
        let fence = s.area.fence().vertices();
        chart
            .draw_series([Polygon::new(
                fence.iter().copied().map(xy).collect::<Vec<_>>(),
                RGBColor(0xf7, 0xf7, 0xf2).filled(),
            )])
            .map_err(draw_error)?;
        chart
            .draw_series([PathElement::new(closed(fence), BLACK.stroke_width(2))])
            .map_err(draw_error)?;
        for cutout in s.area.cutouts() {
            let vertices = cutout.vertices();
            chart
                .draw_series([
                    Polygon::new(
                        vertices.iter().copied().map(xy).collect::<Vec<_>>(),
                        RGBColor(0x9a, 0x9a, 0x9a).filled(),
                    ),
                    Polygon::new(closed(vertices), TRANSPARENT.filled()),
                ])
                .map_err(draw_error)?;
            chart
                .draw_series([PathElement::new(closed(vertices), BLACK.stroke_width(1))])
                .map_err(draw_error)?;
        }
        if let Some(grid) = layers.heat {
            let r = &grid.raster;
            let most = grid.visits.iter().copied().max().unwrap_or(0).max(1);
            let cells = (0..r.rows).flat_map(|row| (0..r.cols).map(move |col| (col, row)));
            chart
                .draw_series(cells.filter_map(|(col, row)| {
                    let visits = grid.visits[row * r.cols + col];
                    (visits > 0 && r.drivable[row * r.cols + col]).then(|| {
                        let low = r.cell_centre(col, row)
                            - Point::new(r.cell_size / 2.0, r.cell_size / 2.0);
                        let high = low + Point::new(r.cell_size, r.cell_size);
                        Rectangle::new([xy(low), xy(high)], heat_colour(visits, most).filled())
                    })
                }))
                .map_err(draw_error)?;
        }
        let start = s.start_route.positions();
        chart
            .draw_series(
                inside_runs(frame, start)
                    .into_iter()
                    .map(|run| PathElement::new(run, RGBColor(0xb0, 0xb0, 0xb0).stroke_width(3))),
            )
            .map_err(draw_error)?;
    }
    // The planned route, each segment from the end of the one before, dashed.
    let mut previous = scenario.and_then(|s| s.start_route.points.last().map(|w| w.position));
    for (k, segment) in layers.segments.iter().enumerate() {
        let points: Vec<Point> = previous
            .into_iter()
            .chain(segment.iter().copied())
            .collect();
        let driven = k < layers.driven;
        let style = if driven {
            PLANNED.stroke_width(2)
        } else {
            PLANNED.mix(0.3).stroke_width(1)
        };
        for run in inside_runs(frame, points) {
            chart
                .draw_series(DashedLineSeries::new(run, 6, 4, style))
                .map_err(draw_error)?;
        }
        previous = segment.last().copied().or(previous);
    }
    for fault in &layers.faults {
        for run in inside_runs(frame, fault.window.iter().copied()) {
            chart
                .draw_series([PathElement::new(run, FAULT.mix(0.35).stroke_width(9))])
                .map_err(draw_error)?;
        }
    }
    for track in &layers.tracks {
        draw_track(&mut chart, frame, track)?;
    }
    for fault in layers.faults.iter().filter(|f| frame.contains(f.at)) {
        chart
            .draw_series([EmptyElement::at(xy(fault.at))
                + Circle::new((0, 0), MARKER_PX, FAULT.stroke_width(2))
                + Circle::new((0, 0), 2, FAULT.filled())])
            .map_err(draw_error)?;
    }
    let mut obstacles = Vec::new();
    if let Some(s) = scenario {
        for anchor in &s.anchors {
            let at = (anchor.x, anchor.y);
            if !frame.contains(Point::new(anchor.x, anchor.y)) {
                continue;
            }
            let name = format!("anchor {}", anchor.id);
            let (px, py) = chart.backend_coord(&at);
            let (w, h) = text_size(&name, LABEL_PX);
            obstacles.push(Rect::around(f64::from(px), f64::from(py), 8.0));
            obstacles.push(Rect::at(f64::from(px + 10), f64::from(py - 4), w, h));
            chart
                .draw_series([EmptyElement::at(at)
                    + TriangleMarker::new((0, 0), 8, RGBColor(0x11, 0x11, 0x88).filled())
                    + Text::new(
                        name,
                        (10, -4),
                        sans(LABEL_PX)
                            .into_font()
                            .color(&RGBColor(0x11, 0x11, 0x88)),
                    )])
                .map_err(draw_error)?;
        }
    }
    draw_map_labels(root, &chart, frame, layers, obstacles)
}

/// A label of a picture: its text, colour, the pixel it labels and whether it is a fault's
/// number (boxed, tied to its marker by a leader line when placed away from it).
struct Label {
    text: String,
    colour: RGBColor,
    at: (f64, f64),
    boxed: bool,
}

/// The segments' and the faults' labels on the map, placed so that none overlaps another, a
/// fault's marker or an anchor (see `labels`).
fn draw_map_labels(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart<'_, '_>,
    frame: &MapFrame,
    layers: &MapLayers<'_>,
    mut obstacles: Vec<Rect>,
) -> Result<(), ReportError> {
    let pixel = |p: Point| {
        let (x, y) = chart.backend_coord(&(p.x, p.y));
        (f64::from(x), f64::from(y))
    };
    let mut labels = Vec::new();
    for (k, segment) in layers.segments.iter().enumerate().take(layers.driven) {
        if let Some(&first) = segment.first().filter(|&&p| frame.contains(p)) {
            labels.push(Label {
                text: format!("s{k}"),
                colour: PLANNED,
                at: pixel(first),
                boxed: false,
            });
        }
    }
    for fault in layers.faults.iter().filter(|f| frame.contains(f.at)) {
        let (x, y) = pixel(fault.at);
        obstacles.push(Rect::around(x, y, f64::from(MARKER_PX) + 1.0));
        if !fault.label.is_empty() {
            labels.push(Label {
                text: fault.label.clone(),
                colour: FAULT,
                at: (x, y),
                boxed: true,
            });
        }
    }
    let candidates: Vec<Vec<Rect>> = labels
        .iter()
        .map(|l| around(l.at.0, l.at.1, text_size(&l.text, LABEL_PX)))
        .collect();
    let placed = place(&candidates, &obstacles, plot_bounds(chart));
    draw_labels(root, &labels, &placed)
}

/// The chart's drawing area in pixels.
fn plot_bounds(chart: &Chart<'_, '_>) -> Rect {
    let (x, y) = chart.plotting_area().get_pixel_range();
    Rect {
        x0: f64::from(x.start),
        y0: f64::from(y.start),
        x1: f64::from(x.end),
        y1: f64::from(y.end),
    }
}

/// Draws `labels` in their `placed` boxes: a fault's number on white in a box of its colour, with
/// a leader line to its marker when the box is not next to it.
fn draw_labels(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    labels: &[Label],
    placed: &[Rect],
) -> Result<(), ReportError> {
    let px = |v: f64| v.round() as i32;
    for (label, r) in labels.iter().zip(placed) {
        let (x, y) = label.at;
        let near = r.nearest(x, y);
        if label.boxed && (near.0 - x).hypot(near.1 - y) > f64::from(MARKER_PX) + 6.0 {
            root.draw(&PathElement::new(
                vec![(px(x), px(y)), (px(near.0), px(near.1))],
                label.colour.stroke_width(1),
            ))
            .map_err(draw_error)?;
        }
        let corners = [(px(r.x0), px(r.y0)), (px(r.x1), px(r.y1))];
        let background = WHITE.mix(if label.boxed { 1.0 } else { 0.75 });
        root.draw(&Rectangle::new(corners, background.filled()))
            .map_err(draw_error)?;
        if label.boxed {
            root.draw(&Rectangle::new(corners, label.colour.stroke_width(1)))
                .map_err(draw_error)?;
        }
        let (cx, cy) = r.centre();
        root.draw(&Text::new(
            label.text.clone(),
            (px(cx), px(cy)),
            sans(LABEL_PX)
                .into_font()
                .color(&label.colour)
                .pos(Pos::new(HPos::Center, VPos::Center)),
        ))
        .map_err(draw_error)?;
    }
    Ok(())
}

/// A tick label with its unit: as many decimals as the value needs, up to two.
fn tick(value: f64, unit: &str) -> String {
    let text = format!("{value:.2}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    let text = if text == "-0" { "0" } else { text };
    format!("{text} {unit}")
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn draw_track(
    chart: &mut Chart<'_, '_>,
    frame: &MapFrame,
    track: &TrackLayer<'_>,
) -> Result<(), ReportError> {
    if track.rtk {
        for run in inside_runs(frame, track.samples.iter().map(|s| s.rtk)) {
            chart
                .draw_series([PathElement::new(run, RTK.stroke_width(1))])
                .map_err(draw_error)?;
        }
    }
    let runs = match track.colouring {
        Colouring::ByDeviation { threshold } => coloured_runs(
            track.samples,
            |s| {
                s.deviation_m
                    .map_or(RED_ABOVE, |d| class_colour(d, threshold))
            },
            |s| Some(s.uwb),
        ),
        Colouring::Run { colour, .. } => coloured_runs(track.samples, |_| colour, |s| Some(s.uwb)),
    };
    for (colour, points) in runs {
        for run in inside_runs(frame, points) {
            chart
                .draw_series([PathElement::new(run, colour.stroke_width(2))])
                .map_err(draw_error)?;
        }
    }
    if let Colouring::Run { threshold, .. } = track.colouring {
        let above = track
            .samples
            .iter()
            .filter(|s| s.deviation_m.is_some_and(|d| d > threshold) && frame.contains(s.uwb));
        chart
            .draw_series(above.map(|s| Circle::new((s.uwb.x, s.uwb.y), 2, RED_ABOVE.filled())))
            .map_err(draw_error)?;
    }
    Ok(())
}

/// A fault's window on the deviation plot.
#[derive(Debug, Clone)]
pub struct Window {
    /// From, seconds since the test began.
    pub from_s: f64,
    /// To.
    pub to_s: f64,
    /// Its label (the probe).
    pub label: String,
}

/// What a deviation plot shows.
#[derive(Debug, Clone)]
pub struct PlotInput<'a> {
    /// The samples (decimated).
    pub samples: &'a [Sample],
    /// The oracle's threshold, metres.
    pub threshold: f64,
    /// The segments' boundaries.
    pub boundaries: &'a [Boundary],
    /// The faults' windows.
    pub windows: &'a [Window],
}

const PLOT_WIDTH: u32 = 860;
const PLOT_HEIGHT: u32 = 320;

/// The deviation plot (see the module doc); `None` without samples. Deviations above five times
/// the threshold are drawn at the top edge.
pub fn deviation_svg(input: &PlotInput<'_>) -> Result<Option<String>, ReportError> {
    let times = input
        .samples
        .iter()
        .map(|s| s.t_s)
        .filter(|t| t.is_finite());
    let (Some(t0), Some(t1)) = (
        times.clone().min_by(f64::total_cmp),
        times.max_by(f64::total_cmp),
    ) else {
        return Ok(None);
    };
    let (t0, t1) = (t0.min(0.0), t1.max(t0.min(0.0) + 1.0));
    let threshold = if input.threshold > 0.0 {
        input.threshold
    } else {
        1.0
    };
    let worst = input
        .samples
        .iter()
        .filter_map(|s| s.deviation_m)
        .fold(0.0, f64::max);
    let top = (worst * 1.1).max(threshold * 1.5).min(threshold * 5.0);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLOT_WIDTH, PLOT_HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(MARGIN)
            .x_label_area_size(X_LABELS)
            .y_label_area_size(Y_LABELS)
            .build_cartesian_2d(t0..t1, 0.0..top)
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .light_line_style(RGBColor(0xf0, 0xf0, 0xf0))
            .bold_line_style(RGBColor(0xdd, 0xdd, 0xdd))
            .x_desc("time since the test began")
            .y_desc("|UWB − RTK|")
            .x_label_formatter(&|v| tick(*v, "s"))
            .y_label_formatter(&|v| tick(*v, "m"))
            .label_style(sans(AXIS_PX))
            .axis_desc_style(sans(AXIS_PX))
            .draw()
            .map_err(draw_error)?;
        // A window of a fraction of a pixel is widened to three pixels, so it stays visible.
        let min_width = (t1 - t0) * 3.0 / f64::from(PLOT_WIDTH - 2 * MARGIN - Y_LABELS);
        let mut labels = Vec::new();
        for w in input.windows {
            let (from, to) = (w.from_s.max(t0), w.to_s.min(t1).max(w.from_s + min_width));
            if from >= t1 || !from.is_finite() || !to.is_finite() {
                continue;
            }
            chart
                .draw_series([Rectangle::new(
                    [(from, 0.0), (to, top)],
                    FAULT.mix(0.18).filled(),
                )])
                .map_err(draw_error)?;
            if !w.label.is_empty() {
                labels.push((w.label.clone(), FAULT, from, true));
            }
        }
        for b in input.boundaries {
            if !(t0..=t1).contains(&b.t_s) {
                continue;
            }
            chart
                .draw_series([PathElement::new(
                    vec![(b.t_s, 0.0), (b.t_s, top)],
                    RGBColor(0x88, 0x88, 0x88).stroke_width(1),
                )])
                .map_err(draw_error)?;
            labels.push((b.label.clone(), RGBColor(0x44, 0x44, 0x44), b.t_s, false));
        }
        chart
            .draw_series(DashedLineSeries::new(
                [(t0, threshold), (t1, threshold)],
                8,
                5,
                RED_ABOVE.stroke_width(1),
            ))
            .map_err(draw_error)?;
        let threshold_text = format!("threshold {threshold:.2} m");
        chart
            .draw_series([Text::new(
                threshold_text.clone(),
                (t0, threshold),
                sans(LABEL_PX)
                    .into_font()
                    .color(&RED_ABOVE)
                    .pos(Pos::new(HPos::Left, VPos::Bottom)),
            )])
            .map_err(draw_error)?;
        let (tx, ty) = chart.backend_coord(&(t0, threshold));
        let (tw, th) = text_size(&threshold_text, LABEL_PX);
        let threshold_box = Rect::at(f64::from(tx), f64::from(ty) - th, tw, th);
        draw_plot_labels(&root, &chart, &labels, threshold_box)?;
        let runs = coloured_runs(
            input.samples,
            |s| {
                s.deviation_m
                    .map_or(RED_ABOVE, |d| class_colour(d, threshold))
            },
            |s| {
                s.deviation_m
                    .map(|d| Point::new(s.t_s, d.min(top)))
                    .filter(|p| p.x >= t0 && p.x <= t1)
            },
        );
        for (colour, points) in runs {
            chart
                .draw_series([PathElement::new(
                    points.into_iter().map(|p| (p.x, p.y)).collect::<Vec<_>>(),
                    colour.stroke_width(2),
                )])
                .map_err(draw_error)?;
        }
        root.present().map_err(draw_error)?;
    }
    Ok(Some(svg))
}

/// The windows' numbers and the segments' names at the top of the plot, each at its time (or
/// to the right of it, tied to it by a line) in the first row where it overlaps no other label
/// nor the threshold's (see `labels`). Each label is (text, colour, time, boxed).
fn draw_plot_labels(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart<'_, '_>,
    labels: &[(String, RGBColor, f64, bool)],
    threshold: Rect,
) -> Result<(), ReportError> {
    let bounds = plot_bounds(chart);
    let labels: Vec<Label> = labels
        .iter()
        .map(|(text, colour, t, boxed)| {
            let (x, _) = chart.backend_coord(&(*t, 0.0));
            Label {
                text: text.clone(),
                colour: *colour,
                at: (f64::from(x), bounds.y0),
                boxed: *boxed,
            }
        })
        .collect();
    let candidates: Vec<Vec<Rect>> = labels
        .iter()
        .map(|l| {
            let size = text_size(&l.text, LABEL_PX);
            rows(l.at.0 + 1.0, bounds.y0 + 1.0, bounds.y1, size)
        })
        .collect();
    let placed = place(&candidates, &[threshold], bounds);
    // The leader of a label moved right runs along its row from its time.
    let anchored: Vec<Label> = labels
        .into_iter()
        .zip(&placed)
        .map(|(l, r)| Label {
            at: (l.at.0, r.centre().1),
            ..l
        })
        .collect();
    draw_labels(root, &anchored, &placed)
}

/// One panel of the coverage chart: a bar per bin, its label under it.
pub struct BarPanel<'a> {
    /// What the bins are (the axis's description).
    pub title: &'a str,
    /// Each bin's label and share of the metres driven (0..=1).
    pub bars: Vec<(String, f64)>,
}

const BARS_HEIGHT: u32 = 230;

/// The coverage chart: the panels one above the other, each the share of the metres driven per
/// bin; `None` without a panel.
pub fn bars_svg(panels: &[BarPanel<'_>]) -> Result<Option<String>, ReportError> {
    if panels.is_empty() {
        return Ok(None);
    }
    let height = BARS_HEIGHT * panels.len() as u32;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLOT_WIDTH, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let areas = root.split_evenly((panels.len(), 1));
        for (area, panel) in areas.iter().zip(panels) {
            draw_bars(area, panel)?;
        }
        root.present().map_err(draw_error)?;
    }
    Ok(Some(svg))
}

fn draw_bars(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    panel: &BarPanel<'_>,
) -> Result<(), ReportError> {
    let n = panel.bars.len().max(1) as f64;
    let most = panel.bars.iter().map(|b| b.1).fold(0.0, f64::max);
    let top = (most * 100.0 * 1.2).clamp(10.0, 100.0);
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d(0.0..n, 0.0..top)
        .map_err(draw_error)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_labels(5)
        .light_line_style(RGBColor(0xf0, 0xf0, 0xf0))
        .bold_line_style(RGBColor(0xdd, 0xdd, 0xdd))
        .x_desc(panel.title)
        .y_desc("share of metres")
        .y_label_formatter(&|v| tick(*v, "%"))
        .label_style(sans(AXIS_PX))
        .axis_desc_style(sans(AXIS_PX))
        .draw()
        .map_err(draw_error)?;
    let font = |colour: &RGBColor, v: VPos| {
        sans(LABEL_PX)
            .into_font()
            .color(colour)
            .pos(Pos::new(HPos::Center, v))
    };
    for (k, (label, share)) in panel.bars.iter().enumerate() {
        let (x, percent) = (k as f64, share * 100.0);
        chart
            .draw_series([Rectangle::new(
                [(x + 0.12, 0.0), (x + 0.88, percent.min(top))],
                PLANNED.filled(),
            )])
            .map_err(draw_error)?;
        let value = format!("{percent:.0} %");
        chart
            .draw_series([
                EmptyElement::at((x + 0.5, 0.0))
                    + Text::new(label.clone(), (0, 6), font(&BLACK, VPos::Top)),
                EmptyElement::at((x + 0.5, percent.min(top)))
                    + Text::new(
                        value,
                        (0, -3),
                        font(&RGBColor(0x33, 0x33, 0x33), VPos::Bottom),
                    ),
            ])
            .map_err(draw_error)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, deviation: f64) -> Sample {
        Sample {
            t_s,
            rtk: Point::new(t_s, 0.0),
            uwb: Point::new(t_s, deviation),
            deviation_m: Some(deviation),
        }
    }

    #[test]
    fn decimation_keeps_the_peaks_in_time_order() {
        let samples: Vec<Sample> = (0..10_000)
            .map(|i| sample(f64::from(i) * 0.05, if i == 4321 { 9.0 } else { 0.1 }))
            .collect();
        let kept = decimate(&samples, MAX_TRACK_POINTS);
        assert!(kept.len() <= MAX_TRACK_POINTS, "{}", kept.len());
        assert!(kept.iter().any(|s| s.deviation_m == Some(9.0)));
        assert!(kept.windows(2).all(|w| w[0].t_s < w[1].t_s));
        assert_eq!(decimate(&samples[..10], MAX_TRACK_POINTS).len(), 10);
    }

    #[test]
    fn the_coverage_chart_has_a_bar_and_a_label_per_bin() {
        let panel = BarPanel {
            title: "speed",
            bars: vec![("0–2 km/h".to_owned(), 0.25), ("2–4 km/h".to_owned(), 0.75)],
        };
        let svg = bars_svg(&[panel]).unwrap().unwrap();
        assert!(
            svg.contains("0–2 km/h") && svg.contains("2–4 km/h"),
            "{svg}"
        );
        assert!(svg.contains("75 %") && svg.contains("25 %"), "{svg}");
        assert!(bars_svg(&[]).unwrap().is_none());
    }

    #[test]
    fn ticks_carry_their_unit_and_no_needless_decimals() {
        assert_eq!(tick(10.0, "m"), "10 m");
        assert_eq!(tick(0.25, "m"), "0.25 m");
        assert_eq!(tick(2.5, "s"), "2.5 s");
        assert_eq!(tick(-0.0001, "m"), "0 m");
    }

    #[test]
    fn colours_follow_the_threshold() {
        assert_eq!(class_colour(0.2, 1.0), GREEN);
        assert_eq!(class_colour(0.5, 1.0), AMBER);
        assert_eq!(class_colour(1.0, 1.0), AMBER);
        assert_eq!(class_colour(1.01, 1.0), RED_ABOVE);
    }

    #[test]
    fn a_plot_and_a_map_are_svg() {
        let samples: Vec<Sample> = (0..100)
            .map(|i| sample(f64::from(i) * 0.1, f64::from(i) * 0.02))
            .collect();
        let windows = [Window {
            from_s: 2.0,
            to_s: 2.01,
            label: "1".to_owned(),
        }];
        let boundaries = [Boundary {
            t_s: 3.0,
            label: "s1".to_owned(),
        }];
        let plot = deviation_svg(&PlotInput {
            samples: &samples,
            threshold: 1.0,
            boundaries: &boundaries,
            windows: &windows,
        })
        .unwrap()
        .unwrap();
        assert!(plot.starts_with("<svg"), "{plot}");
        let text = plot.replace('\n', "");
        assert!(
            text.contains("threshold 1.00 m") && text.contains(">1</text>"),
            "{plot}"
        );
        let layers = MapLayers {
            heat: None,
            segments: vec![vec![Point::new(0.0, 0.0), Point::new(5.0, 1.0)]],
            tracks: vec![TrackLayer {
                samples: &samples,
                colouring: Colouring::ByDeviation { threshold: 1.0 },
                rtk: true,
            }],
            faults: Vec::new(),
            driven: 1,
        };
        let map = map_svg(None, &layers).unwrap().unwrap();
        assert!(map.contains("<polyline"), "{map}");
        assert!(
            map.contains(&css(RED_ABOVE))
                || map.contains("rgb(215,25,28)")
                || map.contains("#D7191C")
        );
        assert!(
            deviation_svg(&PlotInput {
                samples: &[],
                ..PlotInput {
                    samples: &samples,
                    threshold: 1.0,
                    boundaries: &[],
                    windows: &[],
                }
            })
            .unwrap()
            .is_none()
        );
    }
}
