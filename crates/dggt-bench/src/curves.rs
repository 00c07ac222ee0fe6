//! Training curves of one or more runs, read from their `metrics.jsonl` and drawn as one PNG: validation PSNR
//! against step on the left, training loss against step on a log axis on the right, one colour per run. It is
//! what `dggt curves` draws to compare runs (seeds, settings) and what `dggt train` leaves in its run folder as
//! `curves.png`, so that a run's progress is seen at a glance rather than read from JSON lines.
//!
//! The records are those of `dggt_train::records`, read as JSON values (the record types only serialise):
//! `train` records give the loss of each step, `validation` records the PSNR of the trained weights and, once
//! `optim.average` has started, of their average (`"weights": "average"`, drawn dashed and lighter). Records of
//! other kinds are ignored. A skipped step (`"skipped"`), a missing or non-finite value and, on the log axis, a
//! loss that is not positive are left out of the plot. The loss of one step is noisy, so the curve drawn is its
//! running median over [`LOSS_WINDOW`] logged steps centred on each step (fewer at the ends), which also keeps a
//! single spike from bending it; the raw losses lie faintly behind it.
//!
//! Any finite value is drawn, up to the limits of `f64`: the loss axis spans at most [`LOSS_AXIS_DECADES`]
//! powers of ten down from the highest loss (a lower loss lies on its bottom edge), the PSNR axis at most
//! [`PSNR_AXIS_LIMIT`] either side of zero (a PSNR beyond lies on its edge), and every point is drawn within
//! its panel, so that neither plotters' axes nor its lines meet an infinite range.
//!
//! Text needs a font file (the `font` module); without one the curves are drawn without text, with a warning.

use std::path::{Path, PathBuf};
use std::sync::Once;

use dggt_run::metrics::RecordKind;
use dggt_run::run_folder::METRICS;
use dggt_train::records::ScoredWeights;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;
use serde_json::Value;

use crate::error::BenchError;
use crate::font::{FONT_FAMILY, font_available};

/// Width and height of the PNG in pixels.
pub const PNG_SIZE: (u32, u32) = (1280, 560);

/// Logged steps in the running median of the loss.
pub const LOSS_WINDOW: usize = 25;

/// Powers of ten the loss axis spans at most: plotters' log axis needs its end over its start to be finite.
pub const LOSS_AXIS_DECADES: i32 = 300;

/// The largest magnitude the PSNR axis reaches: its width and padding then stay finite.
pub const PSNR_AXIS_LIMIT: f64 = f64::MAX / 8.0;

/// One colour per run, in order (repeating past the tenth run).
const RUN_COLOURS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The colour of the `index`-th run.
pub fn run_colour(index: usize) -> RGBColor {
    RUN_COLOURS[index % RUN_COLOURS.len()]
}

/// A training step that measured a finite loss.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainPoint {
    pub step: u64,
    pub loss: f64,
    /// NaN when the record has none (or a non-finite one).
    pub target_psnr: f64,
}

/// The curves of one run: its steps' losses and its validation PSNR, each sorted by step.
#[derive(Debug, Clone, PartialEq)]
pub struct RunCurves {
    /// The run's name in the legend.
    pub label: String,
    pub train: Vec<TrainPoint>,
    /// (step, PSNR in dB) of the trained weights.
    pub validation_trained: Vec<(u64, f64)>,
    /// (step, PSNR in dB) of the average of the weights (`optim.average`); empty without one.
    pub validation_average: Vec<(u64, f64)>,
}

impl RunCurves {
    /// Reads the curves of the run whose `metrics.jsonl` is `path`, or is in the run folder `path`. A missing
    /// file, a line that is not a JSON record (named by its number) and a file without a training step that has
    /// a finite loss are errors naming the file.
    pub fn read(path: &Path, label: impl Into<String>) -> Result<Self, BenchError> {
        let file = metrics_file(path);
        let text = std::fs::read_to_string(&file)
            .map_err(|e| BenchError::file(&file, format!("cannot read the run's metrics: {e}")))?;
        let mut curves = Self {
            label: label.into(),
            train: Vec::new(),
            validation_trained: Vec::new(),
            validation_average: Vec::new(),
        };
        for (index, line) in text.lines().enumerate().filter(|(_, line)| !line.trim().is_empty()) {
            let bad_line = |detail: String| BenchError::MetricsLine { path: file.clone(), line: index + 1, detail };
            let record: Value = serde_json::from_str(line).map_err(|e| bad_line(format!("not JSON: {e}")))?;
            curves.add(&record).map_err(bad_line)?;
        }
        if curves.train.is_empty() {
            return Err(BenchError::file(&file, "no training step with a finite loss (no `train` record to draw)"));
        }
        curves.train.sort_by_key(|point| point.step);
        curves.validation_trained.sort_by_key(|&(step, _)| step);
        curves.validation_average.sort_by_key(|&(step, _)| step);
        Ok(curves)
    }

    /// Adds what `record` contributes to the curves; `Err` says what is wrong with it.
    fn add(&mut self, record: &Value) -> Result<(), String> {
        let Some(fields) = record.as_object() else { return Err("not a JSON object".into()) };
        let kind = fields.get("kind");
        let train = names(RecordKind::Train, kind);
        if !train && !names(RecordKind::Validation, kind) {
            return Ok(());
        }
        let step = fields.get("step").and_then(Value::as_u64).ok_or_else(|| {
            format!("a `{}` record without a step number", kind.and_then(Value::as_str).unwrap_or_default())
        })?;
        let finite = |key: &str| fields.get(key).and_then(Value::as_f64).filter(|v| v.is_finite());
        if train {
            if let Some(loss) = finite("loss").filter(|_| !fields.contains_key("skipped")) {
                let target_psnr = finite("target_psnr").unwrap_or(f64::NAN);
                self.train.push(TrainPoint { step, loss, target_psnr });
            }
        } else if let Some(psnr) = finite("psnr") {
            let weights = fields.get("weights");
            if weights.is_none() || names(ScoredWeights::Trained, weights) {
                self.validation_trained.push((step, psnr));
            } else if names(ScoredWeights::Average, weights) {
                self.validation_average.push((step, psnr));
            }
        }
        Ok(())
    }

    /// (step, loss) smoothed by the running median of [`LOSS_WINDOW`] logged steps.
    pub fn smoothed_loss(&self) -> Vec<(u64, f64)> {
        let losses: Vec<f64> = self.train.iter().map(|point| point.loss).collect();
        self.train.iter().map(|point| point.step).zip(running_median(&losses, LOSS_WINDOW)).collect()
    }

    /// The last step of the run that has a record.
    fn last_step(&self) -> u64 {
        let last = |series: &[(u64, f64)]| series.last().map_or(0, |&(step, _)| step);
        let train = self.train.last().map_or(0, |point| point.step);
        train.max(last(&self.validation_trained)).max(last(&self.validation_average))
    }
}

/// Whether a record's field `value` is `variant` as the trainer writes it (its serialised form).
fn names(variant: impl Serialize, value: Option<&Value>) -> bool {
    value.is_some_and(|value| serde_json::to_value(variant).is_ok_and(|written| &written == value))
}

/// The metrics file of `path`: itself, or `metrics.jsonl` in it when it is a folder.
fn metrics_file(path: &Path) -> PathBuf {
    if path.is_dir() { path.join(METRICS) } else { path.to_path_buf() }
}

/// A run's default label: the name of its folder (of the folder holding it, for a metrics file).
pub fn default_label(path: &Path) -> String {
    let folder = if path.is_dir() { Some(path) } else { path.parent() };
    let name = folder.and_then(|folder| folder.file_name()).or(path.file_name());
    name.map_or_else(|| path.display().to_string(), |name| name.to_string_lossy().into_owned())
}

/// The (step, PSNR) of the highest PSNR, the earliest on a tie.
pub fn best_point(series: &[(u64, f64)]) -> Option<(u64, f64)> {
    series.iter().copied().reduce(|best, point| if point.1 > best.1 { point } else { best })
}

/// The median of each value and its neighbours, `window` values centred on it (fewer at the ends; an even
/// window takes one more value after it than before). A window of 0 or 1 returns the values as they are.
pub fn running_median(values: &[f64], window: usize) -> Vec<f64> {
    let before = window.saturating_sub(1) / 2;
    let after = window.saturating_sub(1) - before;
    (0..values.len())
        .map(|i| {
            let mut neighbourhood = values[i.saturating_sub(before)..(i + after + 1).min(values.len())].to_vec();
            neighbourhood.sort_by(f64::total_cmp);
            let middle = neighbourhood.len() / 2;
            match neighbourhood.len() % 2 {
                1 => neighbourhood[middle],
                // Without overflow at the limits of f64.
                _ => neighbourhood[middle - 1].midpoint(neighbourhood[middle]),
            }
        })
        .collect()
}

/// Draws the curves of `runs` into the PNG `out` (its folder created if missing), replacing a file there.
pub fn draw_curves(runs: &[RunCurves], out: &Path) -> Result<(), BenchError> {
    if runs.is_empty() {
        return Err(BenchError::setting("runs", "no run to draw"));
    }
    let with_text = font_available();
    if !with_text {
        static WARNED: Once = Once::new();
        WARNED.call_once(|| {
            tracing::warn!("no font file found (set DGGT_PLOT_FONT to a .ttf): training curves are drawn without text");
        });
    }
    if let Some(folder) = out.parent().filter(|folder| !folder.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder)
            .map_err(|e| BenchError::file(folder, format!("cannot create the folder: {e}")))?;
    }
    let (width, height) = PNG_SIZE;
    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    draw(runs, &mut buffer, with_text).map_err(|e| BenchError::file(out, format!("cannot draw the curves: {e}")))?;
    image::save_buffer(out, &buffer, width, height, image::ColorType::Rgb8)
        .map_err(|e| BenchError::file(out, format!("cannot write the PNG: {e}")))
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn draw(runs: &[RunCurves], buffer: &mut [u8], with_text: bool) -> DrawResult {
    let root = BitMapBackend::with_buffer(buffer, PNG_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    let steps = 0.0..(runs.iter().map(RunCurves::last_step).max().unwrap_or(0).max(1) as f64 * 1.02);
    draw_validation(&panels[0], runs, steps.clone(), with_text)?;
    draw_loss(&panels[1], runs, steps, with_text)?;
    root.present()?;
    Ok(())
}

/// A panel's chart: with text, its caption and room for the axis labels.
fn chart_builder<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: &str,
    with_text: bool,
) -> ChartBuilder<'a, 'b, BitMapBackend<'b>> {
    let mut builder = ChartBuilder::on(area);
    builder.margin(18);
    if with_text {
        builder.caption(caption, (FONT_FAMILY, 18)).x_label_area_size(42).y_label_area_size(60);
    }
    builder
}

/// The lowest and highest of `values`, `None` when there are none.
fn value_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |range, v| Some(range.map_or((v, v), |(low, high): (f64, f64)| (low.min(v), high.max(v)))))
}

/// The points of `series`, each value moved into `axis` (a value beyond it lies on its edge).
fn points(series: &[(u64, f64)], axis: &std::ops::Range<f64>) -> Vec<(f64, f64)> {
    series.iter().map(|&(step, value)| (step as f64, value.clamp(axis.start, axis.end))).collect()
}

/// The PSNR axis over the values `low..=high`: padded by 6 % of their spread and at least a decibel and a bit
/// wide, so that a single validation gets readable ticks; within [`PSNR_AXIS_LIMIT`] either side of zero.
fn psnr_axis(low: f64, high: f64) -> std::ops::Range<f64> {
    let (low, high) = (low.clamp(-PSNR_AXIS_LIMIT, PSNR_AXIS_LIMIT), high.clamp(-PSNR_AXIS_LIMIT, PSNR_AXIS_LIMIT));
    let spread = high - low;
    let pad = 0.06 * spread.max(1.0) + 0.5 * (1.0 - spread).max(0.0);
    // Far from zero a decibel is below the values' precision: the axis then keeps a relative width.
    let pad = pad.max(1e-6 * low.abs().max(high.abs()));
    (low - pad)..(high + pad)
}

/// The log axis of the positive losses `low..=high`: 10 % beyond them and at least half as high again as the
/// lowest, ending at most at `f64::MAX` and starting at most [`LOSS_AXIS_DECADES`] powers of ten below its end.
fn loss_axis(low: f64, high: f64) -> std::ops::Range<f64> {
    let end = (high.max(low * 1.5) * 1.1).min(f64::MAX);
    let start = (low * 0.9).max(end / 10f64.powi(LOSS_AXIS_DECADES)).max(f64::from_bits(1));
    start..end
}

/// A legend's sample of a line: 24 pixels of it from the legend's anchor.
fn legend_line(x: i32, y: i32) -> Vec<(i32, i32)> {
    vec![(x, y), (x + 24, y)]
}

fn draw_validation(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    runs: &[RunCurves],
    steps: std::ops::Range<f64>,
    with_text: bool,
) -> DrawResult {
    let all = runs.iter().flat_map(|run| run.validation_trained.iter().chain(&run.validation_average));
    let (psnr, caption) = match value_range(all.map(|&(_, psnr)| psnr)) {
        Some((low, high)) => (psnr_axis(low, high), "validation PSNR (dB)"),
        None => (0.0..1.0, "validation PSNR (dB): no validation records"),
    };
    let mut chart = chart_builder(area, caption, with_text).build_cartesian_2d(steps.clone(), psnr.clone())?;
    if with_text {
        chart
            .configure_mesh()
            .x_desc("step")
            .y_desc("PSNR (dB)")
            .x_label_formatter(&|step| step_label(*step))
            .y_label_formatter(&|psnr| format!("{psnr:.1}"))
            .light_line_style(BLACK.mix(0.05))
            .label_style((FONT_FAMILY, 13))
            .draw()?;
    } else {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(steps.start, psnr.start), (steps.end, psnr.end)],
            BLACK.stroke_width(1),
        )))?;
    }
    for (index, run) in runs.iter().enumerate() {
        let colour = run_colour(index);
        let average = points(&run.validation_average, &psnr);
        if !average.is_empty() {
            let series =
                chart.draw_series(DashedLineSeries::new(average.clone(), 8, 5, colour.mix(0.6).stroke_width(2)))?;
            if with_text {
                series.label(format!("{} (average weights)", run.label)).legend(move |(x, y)| {
                    DashedPathElement::new(legend_line(x, y), 6, 4, colour.mix(0.6).stroke_width(2))
                });
            }
            chart.draw_series(average.iter().map(|&point| Circle::new(point, 3, colour.mix(0.6).stroke_width(1))))?;
        }
        let trained = points(&run.validation_trained, &psnr);
        let series = chart.draw_series(LineSeries::new(trained.clone(), colour.stroke_width(2)))?;
        if with_text {
            series
                .label(run.label.clone())
                .legend(move |(x, y)| PathElement::new(legend_line(x, y), colour.stroke_width(2)));
        }
        chart.draw_series(trained.iter().map(|&point| Circle::new(point, 3, colour.filled())))?;
    }
    if with_text {
        draw_legend(&mut chart, SeriesLabelPosition::LowerRight)?;
    }
    Ok(())
}

fn draw_loss(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    runs: &[RunCurves],
    steps: std::ops::Range<f64>,
    with_text: bool,
) -> DrawResult {
    let positive =
        |series: Vec<(u64, f64)>| -> Vec<(u64, f64)> { series.into_iter().filter(|&(_, loss)| loss > 0.0).collect() };
    let raw: Vec<Vec<(u64, f64)>> =
        runs.iter().map(|run| positive(run.train.iter().map(|p| (p.step, p.loss)).collect())).collect();
    let (low, high) = value_range(raw.iter().flatten().map(|&(_, loss)| loss)).unwrap_or((0.1, 1.0));
    let losses = loss_axis(low, high);
    let raw: Vec<Vec<(f64, f64)>> = raw.iter().map(|series| points(series, &losses)).collect();
    let smoothed: Vec<Vec<(f64, f64)>> =
        runs.iter().map(|run| points(&positive(run.smoothed_loss()), &losses)).collect();
    let caption = format!("training loss (running median of {LOSS_WINDOW} steps)");
    let mut chart =
        chart_builder(area, &caption, with_text).build_cartesian_2d(steps.clone(), losses.clone().log_scale())?;
    if with_text {
        chart
            .configure_mesh()
            .x_desc("step")
            .y_desc("loss (log scale)")
            .x_label_formatter(&|step| step_label(*step))
            // The log axis's own labels repeat each power of ten (plotters 0.3.7): its grid and labels are drawn
            // below instead.
            .disable_y_mesh()
            .y_label_formatter(&|_| String::new())
            .light_line_style(BLACK.mix(0.05))
            .label_style((FONT_FAMILY, 13))
            .draw()?;
    } else {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(steps.start, losses.start), (steps.end, losses.end)],
            BLACK.stroke_width(1),
        )))?;
    }
    for (loss, labelled) in log_ticks(&losses) {
        let grid = BLACK.mix(if labelled { 0.15 } else { 0.05 });
        chart.draw_series(std::iter::once(PathElement::new(vec![(steps.start, loss), (steps.end, loss)], grid)))?;
        if with_text && labelled {
            let (x, y) = chart.backend_coord(&(steps.start, loss));
            let (left, top) = area.get_base_pixel();
            let style = TextStyle::from((FONT_FAMILY, 13)).pos(Pos::new(HPos::Right, VPos::Center));
            area.draw(&Text::new(format_loss(loss), (x - left - 6, y - top), style))?;
        }
    }
    for (index, raw) in raw.into_iter().enumerate() {
        chart.draw_series(LineSeries::new(raw, run_colour(index).mix(0.15)))?;
    }
    for (index, (run, smoothed)) in runs.iter().zip(smoothed).enumerate() {
        let colour = run_colour(index);
        let series = chart.draw_series(LineSeries::new(smoothed, colour.stroke_width(2)))?;
        if with_text {
            series
                .label(run.label.clone())
                .legend(move |(x, y)| PathElement::new(legend_line(x, y), colour.stroke_width(2)));
        }
    }
    if with_text {
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

/// An x-axis tick's label: the step, or nothing between steps (the ticks of a run of a few steps).
fn step_label(step: f64) -> String {
    if step.fract() == 0.0 { format!("{step:.0}") } else { String::new() }
}

/// The grid values of a log axis over `range`: every whole multiple of each power of ten, those at 1, 2 and 5
/// times it labelled (`true`), or all of them when the range holds fewer than two of those.
fn log_ticks(range: &std::ops::Range<f64>) -> Vec<(f64, bool)> {
    let mut ticks = Vec::new();
    if !(range.start > 0.0 && range.end > range.start) {
        return ticks;
    }
    for exponent in range.start.log10().floor() as i32..=range.end.log10().ceil() as i32 {
        for multiple in 1..=9 {
            let value = f64::from(multiple) * 10f64.powi(exponent);
            if range.contains(&value) {
                ticks.push((value, [1, 2, 5].contains(&multiple)));
            }
        }
    }
    if ticks.iter().filter(|&&(_, labelled)| labelled).count() < 2 {
        ticks.iter_mut().for_each(|(_, labelled)| *labelled = true);
    }
    ticks
}

/// A loss tick's label with the decimals its power of ten needs (`0.05`, `0.2`, `1`, `20`), in scientific
/// notation beyond 10^-4..10^5 (`2e-7`, `5e12`).
fn format_loss(loss: f64) -> String {
    let exponent = loss.log10().floor();
    if !(-4.0..=5.0).contains(&exponent) {
        return format!("{loss:e}");
    }
    let decimals = (-exponent).max(0.0) as usize;
    format!("{loss:.decimals$}")
}

fn draw_legend<'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>,
    position: SeriesLabelPosition,
) -> DrawResult {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT_FAMILY, 13))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's records: steps 0 to 3 (step 2 skipped, its loss null), a rolled-back step, validations of the
    /// trained weights (one without `weights`, one with a null PSNR) and of their average, and kinds to ignore.
    const METRICS: &str = r#"{"kind":"train","step":0,"lr_factor":0.1,"loss":0.5,"target_psnr":12.0,"gaussians_kept":10}
{"kind":"train","step":1,"lr_factor":0.2,"loss":0.4,"target_psnr":13.0,"gaussians_kept":10}
{"kind":"validation","step":1,"psnr":20.5,"ssim":0.6}
{"kind":"train","step":2,"lr_factor":0.3,"loss":null,"skipped":"non-finite loss"}
{"kind":"train","step":3,"lr_factor":0.4,"loss":0.3,"target_psnr":null,"gaussians_kept":10,"rolled_back":"weight `w`"}
{"kind":"failure","step":3,"detail":"ignored"}

{"kind":"validation","step":3,"weights":"trained","psnr":21.0,"ssim":0.7}
{"kind":"validation","step":3,"weights":"average","psnr":21.5,"ssim":0.71}
{"kind":"validation","step":4,"weights":"trained","psnr":null,"ssim":0.7}
{"kind":"rollback","step":4}
"#;

    fn run_folder(metrics: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(dggt_run::run_folder::METRICS), metrics).unwrap();
        dir
    }

    #[test]
    fn reads_steps_and_validations_leaving_out_skipped_steps_non_finite_values_and_other_kinds() {
        let dir = run_folder(METRICS);
        let curves = RunCurves::read(dir.path(), "run").unwrap();
        assert_eq!(curves.label, "run");
        let steps: Vec<(u64, f64)> = curves.train.iter().map(|p| (p.step, p.loss)).collect();
        assert_eq!(steps, [(0, 0.5), (1, 0.4), (3, 0.3)]);
        assert_eq!(curves.train[1].target_psnr, 13.0);
        assert!(curves.train[2].target_psnr.is_nan(), "a null target PSNR reads as NaN");
        assert_eq!(curves.validation_trained, [(1, 20.5), (3, 21.0)]);
        assert_eq!(curves.validation_average, [(3, 21.5)]);
        let file = RunCurves::read(&dir.path().join(dggt_run::run_folder::METRICS), "run").unwrap();
        // Compared as text: the NaN target PSNR is not equal to itself.
        assert_eq!(format!("{file:?}"), format!("{curves:?}"), "the run folder and its metrics file read alike");
        let name = dir.path().file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(default_label(dir.path()), name);
        assert_eq!(default_label(&dir.path().join(dggt_run::run_folder::METRICS)), name);
        assert_eq!(best_point(&[(1, 20.0), (2, 22.0), (3, 22.0), (4, 21.0)]), Some((2, 22.0)));
    }

    #[test]
    fn the_loss_is_smoothed_by_a_centred_running_median() {
        assert_eq!(running_median(&[1.0, 9.0, 2.0, 3.0, 100.0, 4.0, 5.0], 3), [5.0, 2.0, 3.0, 3.0, 4.0, 5.0, 4.5]);
        assert_eq!(running_median(&[3.0, 1.0, 2.0], 1), [3.0, 1.0, 2.0], "a window of one keeps the values");
        assert_eq!(running_median(&[], LOSS_WINDOW), Vec::<f64>::new());
        // A single spike among steady losses does not move the curve.
        let mut losses = vec![0.1; 60];
        losses[30] = 50.0;
        assert!(running_median(&losses, LOSS_WINDOW).iter().all(|&v| v == 0.1));
        let dir = run_folder(METRICS);
        let smoothed = RunCurves::read(dir.path(), "run").unwrap().smoothed_loss();
        assert_eq!(smoothed, [(0, 0.4), (1, 0.4), (3, 0.4)], "three losses all within the window: their median");
    }

    #[test]
    fn a_corrupt_line_is_an_error_naming_the_file_and_the_line() {
        let dir = run_folder(&METRICS.replace(r#"{"kind":"failure","step":3,"detail":"ignored"}"#, "{\"kind\":"));
        let error = RunCurves::read(dir.path(), "run").unwrap_err();
        let file = dir.path().join(dggt_run::run_folder::METRICS);
        assert!(matches!(&error, BenchError::MetricsLine { path, line: 6, .. } if *path == file), "{error:?}");
        let text = error.to_string();
        assert!(text.contains(&file.display().to_string()) && text.contains("line 6"), "{text}");
        let dir = run_folder(r#"{"kind":"train","loss":0.5}"#);
        let text = RunCurves::read(dir.path(), "run").unwrap_err().to_string();
        assert!(text.contains("line 1") && text.contains("without a step"), "{text}");
    }

    #[test]
    fn a_missing_or_empty_file_or_one_without_training_steps_is_an_error_naming_it() {
        let validation_only = r#"{"kind":"validation","step":1,"psnr":20.5}"#;
        for metrics in ["", "\n\n", validation_only] {
            let dir = run_folder(metrics);
            let error = RunCurves::read(dir.path(), "run").unwrap_err();
            let file = dir.path().join(dggt_run::run_folder::METRICS);
            assert!(matches!(&error, BenchError::File { path, .. } if *path == file), "{metrics:?}: {error:?}");
            assert!(error.to_string().contains("no training step"), "{error}");
        }
        let dir = tempfile::tempdir().unwrap();
        let error = RunCurves::read(dir.path(), "run").unwrap_err().to_string();
        assert!(error.contains(&dir.path().join(dggt_run::run_folder::METRICS).display().to_string()), "{error}");
    }

    #[test]
    fn log_ticks_label_one_two_and_five_times_each_power_of_ten() {
        let ticks = log_ticks(&(0.015..0.6));
        let labelled: Vec<String> = ticks.iter().filter(|t| t.1).map(|t| format_loss(t.0)).collect();
        assert_eq!(labelled, ["0.02", "0.05", "0.1", "0.2", "0.5"]);
        assert_eq!(ticks.len(), 8 + 5, "0.02 to 0.09, then 0.1 to 0.5");
        let narrow: Vec<String> = log_ticks(&(0.35..0.65)).iter().filter(|t| t.1).map(|t| format_loss(t.0)).collect();
        assert_eq!(narrow, ["0.4", "0.5", "0.6"], "a range with one of 1, 2 or 5 labels every tick");
    }

    /// Runs `work` on its own thread and returns its result, failing when it takes more than a minute (a loop
    /// that does not end) or panics.
    fn returns_in_time<T: Send + 'static>(what: &str, work: impl FnOnce() -> T + Send + 'static) -> T {
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::spawn(move || sender.send(work()));
        match receiver.recv_timeout(std::time::Duration::from_secs(60)) {
            Ok(result) => result,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => panic!("{what}: did not return within a minute"),
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => panic!("{what}: panicked"),
        }
    }

    /// Losses and PSNRs at and near the limits of f64, alone and mixed with ordinary and opposite extremes.
    const EXTREME_SERIES: [&[f64]; 9] = [
        &[1e308],
        &[f64::MAX, f64::MAX],
        &[f64::MAX, 1e308, 0.5],
        &[f64::MIN_POSITIVE],
        &[f64::MIN_POSITIVE, f64::MAX],
        &[5e-324, 1e308, 0.3, f64::MIN_POSITIVE],
        &[1e-300, 1e300],
        &[-f64::MAX, f64::MAX, 1.0],
        &[0.25, 1e308, 0.25, 0.25],
    ];

    /// A metrics file whose steps have `values` as loss and (a validation after each) as PSNR.
    fn extreme_metrics(values: &[f64]) -> String {
        let mut lines = String::new();
        for (step, value) in values.iter().enumerate() {
            let value = serde_json::to_string(value).unwrap();
            lines.push_str(&format!(
                "{{\"kind\":\"train\",\"step\":{step},\"loss\":{value},\"target_psnr\":{value}}}\n"
            ));
            lines.push_str(&format!("{{\"kind\":\"validation\",\"step\":{step},\"psnr\":{value}}}\n"));
            lines.push_str(&format!(
                "{{\"kind\":\"validation\",\"step\":{step},\"weights\":\"average\",\"psnr\":{value}}}\n"
            ));
        }
        lines
    }

    #[test]
    fn values_at_the_limits_of_f64_are_read_smoothed_and_drawn() {
        for values in EXTREME_SERIES {
            let dir = run_folder(&extreme_metrics(values));
            let curves = RunCurves::read(dir.path(), "extreme").unwrap();
            let losses: Vec<f64> = curves.train.iter().map(|point| point.loss).collect();
            assert_eq!(losses, values, "every finite loss is kept as written");
            assert_eq!(curves.validation_trained.len(), values.len(), "{values:?}");
            let smoothed = curves.smoothed_loss();
            assert!(smoothed.iter().all(|&(_, loss)| loss.is_finite()), "{values:?}: {smoothed:?}");
            for with_text in [false, font_available()] {
                let runs = vec![curves.clone()];
                let buffer = returns_in_time(&format!("drawing {values:?}"), move || {
                    let (width, height) = PNG_SIZE;
                    let mut buffer = vec![255u8; width as usize * height as usize * 3];
                    draw(&runs, &mut buffer, with_text).map_err(|e| e.to_string()).map(|()| buffer)
                });
                let buffer = buffer.unwrap_or_else(|e| panic!("{values:?}: {e}"));
                assert!(left_half_has(&buffer, run_colour(0)), "{values:?}: the PSNR is drawn");
            }
        }
    }

    #[test]
    fn axes_and_medians_stay_finite_and_bounded_at_the_limits_of_f64() {
        assert_eq!(running_median(&[f64::MAX, f64::MAX], 2), [f64::MAX, f64::MAX], "no overflow to infinity");
        assert_eq!(running_median(&[-f64::MAX, f64::MAX], 2), [0.0, f64::MAX]);
        assert_eq!(running_median(&[5e-324, 5e-324], 2), [5e-324, 5e-324], "no underflow to zero");
        let extremes = [f64::MIN_POSITIVE, 5e-324, 1e-300, 0.5, 1e300, 1e308, f64::MAX];
        for &low in &extremes {
            for &high in extremes.iter().filter(|&&high| high >= low) {
                let axis = loss_axis(low, high);
                assert!(axis.start > 0.0 && axis.end.is_finite() && axis.start < axis.end, "{low}..{high}: {axis:?}");
                assert!((axis.end / axis.start).is_finite(), "{low}..{high}: plotters divides the ends: {axis:?}");
                assert!(axis.end >= high, "{low}..{high}: the highest loss is on the axis: {axis:?}");
                let ticks = returns_in_time("log ticks", move || log_ticks(&axis));
                assert!(ticks.len() <= 9 * (LOSS_AXIS_DECADES as usize + 3), "{low}..{high}: {} ticks", ticks.len());
                assert!(ticks.iter().all(|(tick, _)| tick.is_finite() && !format_loss(*tick).is_empty()));
                let psnr = psnr_axis(-high, high);
                assert!(psnr.start < psnr.end && (psnr.end - psnr.start).is_finite(), "{high}: {psnr:?}");
            }
        }
        assert_eq!(format_loss(1e308), "1e308");
        assert_eq!(format_loss(2e-7), "2e-7");
    }

    /// Whether the left half of the RGB `buffer` has a pixel of `colour`.
    fn left_half_has(buffer: &[u8], colour: RGBColor) -> bool {
        let (width, _) = PNG_SIZE;
        let RGBColor(r, g, b) = colour;
        buffer.chunks_exact(3).enumerate().any(|(i, p)| (i as u32 % width) < width / 2 && p == [r, g, b])
    }

    #[test]
    fn the_png_has_its_size_and_each_run_colour_in_the_validation_panel() {
        let dir = run_folder(METRICS);
        let first = RunCurves::read(dir.path(), "first").unwrap();
        let mut second = first.clone();
        second.label = "second".into();
        second.validation_trained.iter_mut().for_each(|(_, psnr)| *psnr -= 1.0);
        let out = dir.path().join("plots/curves.png");
        draw_curves(&[first.clone(), second.clone()], &out).unwrap();
        let png = image::open(&out).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), PNG_SIZE);
        for index in 0..2 {
            assert!(left_half_has(png.as_raw(), run_colour(index)), "run {index}'s colour");
        }
        assert!(!left_half_has(png.as_raw(), run_colour(2)), "no third run");

        // Without a font: the same lines, no text.
        let (width, height) = PNG_SIZE;
        let mut buffer = vec![255u8; width as usize * height as usize * 3];
        draw(&[first, second], &mut buffer, false).unwrap();
        assert!(left_half_has(&buffer, run_colour(0)) && left_half_has(&buffer, run_colour(1)));
    }
}
