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
use super::route::Boundary;

/// The most samples a track is drawn with (see [`decimate`]).
pub(crate) const MAX_TRACK_POINTS: usize = 2000;

/// Green: below half the threshold.
pub(crate) const GREEN: RGBColor = RGBColor(0x1a, 0x98, 0x50);
/// Amber: up to the threshold.
pub(crate) const AMBER: RGBColor = RGBColor(0xe6, 0x8a, 0x00);
/// Red: above the threshold.
pub(crate) const RED_ABOVE: RGBColor = RGBColor(0xd7, 0x19, 0x1c);
/// The faults' places and windows.
pub(crate) const FAULT: RGBColor = RGBColor(0x7b, 0x32, 0x94);
/// The RTK track.
const RTK: RGBColor = RGBColor(0x25, 0x25, 0x25);
/// The planned route.
const PLANNED: RGBColor = RGBColor(0x4a, 0x7f, 0xc1);
/// Colours of the runs of a replay, in order.
pub(crate) const RUN_COLOURS: [RGBColor; 6] = [
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
pub(crate) fn css(colour: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", colour.0, colour.1, colour.2)
}

/// The colour of a deviation against `threshold`.
pub(crate) fn class_colour(deviation: f64, threshold: f64) -> RGBColor {
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
pub(crate) fn decimate(samples: &[Sample], max: usize) -> Vec<Sample> {
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
pub(crate) enum Colouring {
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
pub(crate) struct TrackLayer<'a> {
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
pub(crate) struct FaultMark {
    /// The place.
    pub at: Point,
    /// Its label (the probe).
    pub label: String,
    /// The RTK track during its window.
    pub window: Vec<Point>,
}

/// What a map shows.
#[derive(Debug, Clone, Default)]
pub(crate) struct MapLayers<'a> {
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
const Y_LABELS: u32 = 50;
const X_LABELS: u32 = 36;

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
pub(crate) fn map_svg(
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
        .x_desc("east, m")
        .y_desc("north, m")
        .label_style(("sans-serif", 12))
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
        if let Some(&first) = segment.first().filter(|&&p| driven && frame.contains(p)) {
            chart
                .draw_series([Text::new(
                    format!("s{k}"),
                    xy(first),
                    ("sans-serif", 11).into_font().color(&PLANNED),
                )])
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
    for fault in &layers.faults {
        if !frame.contains(fault.at) {
            continue;
        }
        chart
            .draw_series([EmptyElement::at(xy(fault.at))
                + Circle::new((0, 0), 6, FAULT.stroke_width(2))
                + Circle::new((0, 0), 2, FAULT.filled())])
            .map_err(draw_error)?;
        if !fault.label.is_empty() {
            chart
                .draw_series([EmptyElement::at(xy(fault.at))
                    + Text::new(
                        fault.label.clone(),
                        (8, -14),
                        ("sans-serif", 12).into_font().color(&FAULT),
                    )])
                .map_err(draw_error)?;
        }
    }
    if let Some(s) = scenario {
        for anchor in &s.anchors {
            let at = (anchor.x, anchor.y);
            if !frame.contains(Point::new(anchor.x, anchor.y)) {
                continue;
            }
            chart
                .draw_series([EmptyElement::at(at)
                    + TriangleMarker::new((0, 0), 8, RGBColor(0x11, 0x11, 0x88).filled())
                    + Text::new(
                        format!("anchor {}", anchor.id),
                        (10, -4),
                        ("sans-serif", 12)
                            .into_font()
                            .color(&RGBColor(0x11, 0x11, 0x88)),
                    )])
                .map_err(draw_error)?;
        }
    }
    Ok(())
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
pub(crate) struct Window {
    /// From, seconds since the test began.
    pub from_s: f64,
    /// To.
    pub to_s: f64,
    /// Its label (the probe).
    pub label: String,
}

/// What a deviation plot shows.
#[derive(Debug, Clone)]
pub(crate) struct PlotInput<'a> {
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
const PLOT_HEIGHT: u32 = 290;

/// The deviation plot (see the module doc); `None` without samples. Deviations above five times
/// the threshold are drawn at the top edge.
pub(crate) fn deviation_svg(input: &PlotInput<'_>) -> Result<Option<String>, ReportError> {
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
            .x_desc("seconds since the test began")
            .y_desc("|UWB − RTK|, m")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(draw_error)?;
        // A window of a fraction of a pixel is widened to three pixels, so it stays visible.
        let min_width = (t1 - t0) * 3.0 / f64::from(PLOT_WIDTH - 2 * MARGIN - Y_LABELS);
        // Labels in rows from the top: the windows' in the first two, the boundaries' in the third.
        let plot_h = f64::from(PLOT_HEIGHT - 2 * MARGIN - X_LABELS);
        let row = |r: usize| top * (1.0 - 13.0 * r as f64 / plot_h);
        for (i, w) in input.windows.iter().enumerate() {
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
            chart
                .draw_series([Text::new(
                    w.label.clone(),
                    (from, row(i % 2)),
                    ("sans-serif", 11)
                        .into_font()
                        .color(&FAULT)
                        .pos(Pos::new(HPos::Left, VPos::Top)),
                )])
                .map_err(draw_error)?;
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
            chart
                .draw_series([Text::new(
                    b.label.clone(),
                    (b.t_s, row(2)),
                    ("sans-serif", 11)
                        .into_font()
                        .color(&RGBColor(0x55, 0x55, 0x55))
                        .pos(Pos::new(HPos::Left, VPos::Top)),
                )])
                .map_err(draw_error)?;
        }
        chart
            .draw_series(DashedLineSeries::new(
                [(t0, threshold), (t1, threshold)],
                8,
                5,
                RED_ABOVE.stroke_width(1),
            ))
            .map_err(draw_error)?;
        chart
            .draw_series([Text::new(
                format!("threshold {threshold:.2} m"),
                (t0, threshold),
                ("sans-serif", 11)
                    .into_font()
                    .color(&RED_ABOVE)
                    .pos(Pos::new(HPos::Left, VPos::Bottom)),
            )])
            .map_err(draw_error)?;
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
            label: "uwb_yaw".to_owned(),
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
        assert!(plot.contains("threshold 1.00 m") && plot.contains("uwb_yaw"));
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
