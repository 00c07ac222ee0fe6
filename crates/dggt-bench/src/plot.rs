//! The sweep as a picture: PSNR against total time, one panel against the exact render and one against
//! ground truth, points coloured by the knob their row varies, each labelled with its value, the Pareto front
//! ringed and joined.
//!
//! `bench.png` is drawn with plotters. Its text needs a font file, looked up at run time (the `font` module);
//! none is shipped. Without one the PNG has points and lines only, and `bench.svg` — written by hand here, its
//! text drawn by whatever displays it — always carries the labels. An infinite PSNR (an exact match) is drawn
//! at the top of its panel and labelled `(identical)`.

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;

use crate::error::BenchError;
use crate::font::{FONT_FAMILY, font_available};
use crate::knobs::{Configuration, Varied};
use crate::run::{BenchReport, MeasuredRow};
use dggt_infer::SkyChoice;

/// Width and height of `bench.png` (and of `bench.svg`) in pixels.
pub const PNG_SIZE: (u32, u32) = (1280, 560);

/// Which error a panel plots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Panel {
    Exact,
    Truth,
}

impl Panel {
    fn title(self, report: &BenchReport) -> String {
        match self {
            Self::Exact => "PSNR vs exact render (dB) against total time (ms)".into(),
            Self::Truth if report.truth_meaningful => "PSNR vs ground truth (dB) against total time (ms)".into(),
            Self::Truth => "PSNR vs ground truth (dB): untrained model, meaningless".into(),
        }
    }

    fn psnr(self, row: &MeasuredRow) -> f64 {
        match self {
            Self::Exact => row.vs_exact.psnr_db,
            Self::Truth => row.vs_truth.psnr_db,
        }
    }

    fn front(self, row: &MeasuredRow) -> bool {
        match self {
            Self::Exact => row.pareto_vs_exact,
            Self::Truth => row.pareto_vs_truth,
        }
    }
}

/// One point of a panel.
struct PlotPoint {
    time_ms: f64,
    /// Finite: an infinite PSNR is placed at the top of the range.
    psnr_db: f64,
    front: bool,
    varied: Varied,
    label: String,
}

struct PanelData {
    points: Vec<PlotPoint>,
    x_range: (f64, f64),
    y_range: (f64, f64),
}

/// The value a row varies, e.g. `w112`, `f4`, `o0.05`, `f16`, `nosky`; `exact` and `base` for those rows.
pub fn short_label(configuration: &Configuration) -> String {
    let k = &configuration.knobs;
    match configuration.varied {
        Varied::Reference => "exact".into(),
        Varied::Baseline => "base".into(),
        Varied::Width => format!("w{}", k.width),
        Varied::InputFrames => format!("{} frames", k.input_frames),
        Varied::MinOpacity => format!("o{}", k.culling.label()),
        Varied::Precision => k.precision.name().into(),
        Varied::Sky => if k.sky == SkyChoice::Render { "sky" } else { "no sky" }.into(),
        Varied::Skips => format!("skip {}", k.skips.name()),
        Varied::Motion => k.motion.name().into(),
        Varied::Grid => k.label(),
    }
}

fn colour(varied: Varied) -> RGBColor {
    match varied {
        Varied::Reference => RGBColor(0, 0, 0),
        Varied::Baseline => RGBColor(31, 119, 180),
        Varied::Width => RGBColor(255, 127, 14),
        Varied::InputFrames => RGBColor(44, 160, 44),
        Varied::MinOpacity => RGBColor(214, 39, 40),
        Varied::Precision => RGBColor(148, 103, 189),
        Varied::Sky => RGBColor(140, 86, 75),
        Varied::Skips => RGBColor(23, 190, 207),
        Varied::Motion => RGBColor(188, 189, 34),
        Varied::Grid => RGBColor(127, 127, 127),
    }
}

const GROUPS: [Varied; 10] = [
    Varied::Reference,
    Varied::Baseline,
    Varied::Width,
    Varied::InputFrames,
    Varied::MinOpacity,
    Varied::Precision,
    Varied::Sky,
    Varied::Skips,
    Varied::Motion,
    Varied::Grid,
];

fn panel_data(report: &BenchReport, panel: Panel) -> PanelData {
    let rows: Vec<&MeasuredRow> = report.rows.iter().filter_map(|r| r.measured()).collect();
    let finite: Vec<f64> = rows.iter().map(|r| panel.psnr(r)).filter(|v| v.is_finite()).collect();
    let (mut low, mut high) = finite.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    if !low.is_finite() {
        (low, high) = (0.0, 1.0);
    }
    let span = (high - low).max(2.0);
    let has_infinite = rows.iter().any(|r| panel.psnr(r) == f64::INFINITY);
    let top = if has_infinite { high + 0.15 * span } else { high };
    // Room below the points for the legend.
    let y_range = (low - 0.4 * span, top + 0.08 * span);
    let max_time = rows.iter().map(|r| r.times.total_ms).filter(|t| t.is_finite()).fold(0.0, f64::max);
    let x_range = (0.0, (max_time * 1.12).max(1e-3));
    let points = rows
        .iter()
        .filter(|r| !panel.psnr(r).is_nan())
        .map(|r| {
            let value = panel.psnr(r);
            let infinite = value == f64::INFINITY;
            let mut label = short_label(&r.configuration);
            if infinite && r.configuration.varied != Varied::Reference {
                label.push_str(" (identical)");
            }
            PlotPoint {
                time_ms: r.times.total_ms,
                psnr_db: if infinite { top } else { value.max(y_range.0) },
                front: panel.front(r),
                varied: r.configuration.varied,
                label,
            }
        })
        .collect();
    PanelData { points, x_range, y_range }
}

/// Label positions (pixels) for points at `anchors` (pixels): each label starts just right of and above its
/// point and moves down a line at a time while it would cover another point or a label already placed (labels
/// are placed top to bottom). Returns each label's top.
fn place_labels(anchors: &[(f64, f64)]) -> Vec<f64> {
    const LINE: f64 = 13.0;
    const LABEL_WIDTH: f64 = 80.0;
    const POINT_RADIUS: f64 = 9.0;
    let mut order: Vec<usize> = (0..anchors.len()).collect();
    order.sort_by(|&a, &b| anchors[a].1.total_cmp(&anchors[b].1));
    let mut placed: Vec<(f64, f64)> = Vec::new();
    let mut label_y = vec![0.0; anchors.len()];
    for i in order {
        let (x, anchor_y) = anchors[i];
        let left = x + 8.0;
        let mut y = anchor_y - 16.0;
        for _ in 0..12 {
            let covers_point = anchors.iter().enumerate().any(|(k, &(ax, ay))| {
                k != i
                    && ax + POINT_RADIUS > left
                    && ax - POINT_RADIUS < left + LABEL_WIDTH
                    && ay + POINT_RADIUS > y
                    && ay - POINT_RADIUS < y + LINE
            });
            let covers_label = placed.iter().any(|&(px, py)| (px - x).abs() < LABEL_WIDTH && (py - y).abs() < LINE);
            if !covers_point && !covers_label {
                break;
            }
            y += LINE;
        }
        placed.push((x, y));
        label_y[i] = y;
    }
    label_y
}

fn front_line(points: &[PlotPoint]) -> Vec<(f64, f64)> {
    let mut line: Vec<(f64, f64)> = points.iter().filter(|p| p.front).map(|p| (p.time_ms, p.psnr_db)).collect();
    line.sort_by(|a, b| a.0.total_cmp(&b.0));
    line
}

/// Draws `bench.png`; returns whether it has text.
pub fn write_png(report: &BenchReport, path: &Path) -> Result<bool, BenchError> {
    let with_text = font_available();
    let (width, height) = PNG_SIZE;
    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    draw(report, &mut buffer, with_text).map_err(|e| BenchError::file(path, format!("cannot draw the plot: {e}")))?;
    image::save_buffer(path, &buffer, width, height, image::ColorType::Rgb8)
        .map_err(|e| BenchError::file(path, format!("cannot write the PNG: {e}")))?;
    Ok(with_text)
}

fn draw(report: &BenchReport, buffer: &mut [u8], with_text: bool) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::with_buffer(buffer, PNG_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, 2));
    for (area, panel) in areas.iter().zip([Panel::Exact, Panel::Truth]) {
        let data = panel_data(report, panel);
        let mut builder = ChartBuilder::on(area);
        builder.margin(18);
        if with_text {
            builder.caption(panel.title(report), (FONT_FAMILY, 17)).x_label_area_size(42).y_label_area_size(52);
        }
        let mut chart = builder.build_cartesian_2d(data.x_range.0..data.x_range.1, data.y_range.0..data.y_range.1)?;
        if with_text {
            chart
                .configure_mesh()
                .x_desc("total time per row (ms)")
                .y_desc("PSNR (dB)")
                .label_style((FONT_FAMILY, 13))
                .draw()?;
        } else {
            let (x, y) = (data.x_range, data.y_range);
            chart.draw_series(std::iter::once(Rectangle::new([(x.0, y.0), (x.1, y.1)], BLACK.stroke_width(1))))?;
        }
        chart.draw_series(LineSeries::new(front_line(&data.points), BLACK.stroke_width(2)))?;
        chart.draw_series(
            data.points
                .iter()
                .filter(|p| p.front)
                .map(|p| Circle::new((p.time_ms, p.psnr_db), 9, BLACK.stroke_width(2))),
        )?;
        for group in GROUPS {
            let members: Vec<&PlotPoint> = data.points.iter().filter(|p| p.varied == group).collect();
            if members.is_empty() {
                continue;
            }
            let fill = colour(group);
            let series =
                chart.draw_series(members.iter().map(|p| Circle::new((p.time_ms, p.psnr_db), 5, fill.filled())))?;
            if with_text {
                series.label(group.name()).legend(move |(x, y)| Circle::new((x, y), 5, fill.filled()));
            }
        }
        if with_text {
            let anchors: Vec<(f64, f64)> = data
                .points
                .iter()
                .map(|p| {
                    let (x, y) = chart.backend_coord(&(p.time_ms, p.psnr_db));
                    (x as f64, y as f64)
                })
                .collect();
            let label_y = place_labels(&anchors);
            chart.draw_series(data.points.iter().zip(anchors.iter().zip(label_y)).map(|(p, (anchor, y))| {
                let offset = (8, (y - anchor.1).round() as i32);
                EmptyElement::at((p.time_ms, p.psnr_db))
                    + Text::new(p.label.clone(), offset, (FONT_FAMILY, 12).into_font().color(&BLACK))
            }))?;
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font((FONT_FAMILY, 12))
                .draw()?;
        }
    }
    root.present()?;
    Ok(())
}

/// The same plot as SVG, text included (no font file needed to write it).
pub fn svg_text(report: &BenchReport) -> String {
    let (width, height) = PNG_SIZE;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" \
         font-family=\"sans-serif\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    let panel_width = width as f64 / 2.0;
    for (k, panel) in [Panel::Exact, Panel::Truth].into_iter().enumerate() {
        let data = panel_data(report, panel);
        let (left, right, top, bottom) =
            (k as f64 * panel_width + 70.0, (k + 1) as f64 * panel_width - 20.0, 45.0, height as f64 - 55.0);
        let x = |v: f64| left + (v - data.x_range.0) / (data.x_range.1 - data.x_range.0) * (right - left);
        let y = |v: f64| bottom - (v - data.y_range.0) / (data.y_range.1 - data.y_range.0) * (bottom - top);
        let _ = writeln!(
            svg,
            "<text x=\"{:.1}\" y=\"25\" font-size=\"16\" text-anchor=\"middle\">{}</text>",
            (left + right) / 2.0,
            escape(&panel.title(report))
        );
        let _ = writeln!(
            svg,
            "<rect x=\"{left:.1}\" y=\"{top:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"black\"/>",
            right - left,
            bottom - top
        );
        for i in 0..=5 {
            let fraction = i as f64 / 5.0;
            let tx = data.x_range.0 + fraction * (data.x_range.1 - data.x_range.0);
            let ty = data.y_range.0 + fraction * (data.y_range.1 - data.y_range.0);
            let _ = writeln!(
                svg,
                "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\" text-anchor=\"middle\">{tx:.0}</text>\n\
                 <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\" text-anchor=\"end\">{ty:.1}</text>",
                x(tx),
                bottom + 18.0,
                left - 6.0,
                y(ty) + 4.0
            );
        }
        let _ = writeln!(
            svg,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"13\" text-anchor=\"middle\">total time per row (ms)</text>\n\
             <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"13\" text-anchor=\"middle\" transform=\"rotate(-90 {:.1} {:.1})\">PSNR (dB)</text>",
            (left + right) / 2.0,
            bottom + 40.0,
            left - 50.0,
            (top + bottom) / 2.0,
            left - 50.0,
            (top + bottom) / 2.0
        );
        let line: Vec<String> =
            front_line(&data.points).iter().map(|&(t, p)| format!("{:.1},{:.1}", x(t), y(p))).collect();
        let _ = writeln!(
            svg,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"black\" stroke-width=\"2\"/>",
            line.join(" ")
        );
        let anchors: Vec<(f64, f64)> = data.points.iter().map(|p| (x(p.time_ms), y(p.psnr_db))).collect();
        // SVG text is placed by its baseline: a line below the top the placement works with.
        let label_y = place_labels(&anchors);
        for (p, label_y) in data.points.iter().zip(label_y) {
            let RGBColor(r, g, b) = colour(p.varied);
            if p.front {
                let _ = writeln!(
                    svg,
                    "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"9\" fill=\"none\" stroke=\"black\" stroke-width=\"2\"/>",
                    x(p.time_ms),
                    y(p.psnr_db)
                );
            }
            let _ = writeln!(
                svg,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"5\" fill=\"rgb({r},{g},{b})\"/>\n\
                 <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\">{}</text>",
                x(p.time_ms),
                y(p.psnr_db),
                x(p.time_ms) + 8.0,
                label_y + 11.0,
                escape(&p.label)
            );
        }
        let mut legend_y = bottom - 12.0;
        for group in GROUPS.iter().rev().filter(|g| data.points.iter().any(|p| p.varied == **g)) {
            let RGBColor(r, g, b) = colour(*group);
            let _ = writeln!(
                svg,
                "<circle cx=\"{:.1}\" cy=\"{legend_y:.1}\" r=\"5\" fill=\"rgb({r},{g},{b})\"/>\n\
                 <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"12\">{}</text>",
                right - 95.0,
                right - 85.0,
                legend_y + 4.0,
                group.name()
            );
            legend_y -= 16.0;
        }
    }
    svg.push_str("</svg>\n");
    svg
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}
