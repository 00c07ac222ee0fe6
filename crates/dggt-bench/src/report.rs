//! The sweep's table: `bench.csv` (one row per configuration, units in the header), `bench-notes.txt` (what
//! the numbers mean, what is not swept, what was skipped), and a plain-text table for the terminal.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::BenchError;
use crate::run::{BenchReport, ErrorMetrics, MeasuredRow, RowOutcome};
use dggt_infer::SkyChoice;

/// The CSV header; the unit of each column is in its name (`_ms`, `_px`, `_db`) or is none.
pub const CSV_HEADER: &str = "row,varied,label,width_px,height_px,input_frames,min_opacity,precision,sky,skips,\
motion,backbone_ms,heads_ms,assembly_ms,raster_ms,total_ms,gaussians_kept_per_view,gaussian_candidates_per_view,\
sky_gaussians,motion_skipped_frames,sky_skipped_views,psnr_vs_exact_db,ssim_vs_exact,lpips_vs_exact,\
psnr_vs_truth_db,ssim_vs_truth,lpips_vs_truth,refine_ms,psnr_refined_vs_truth_db,ssim_refined_vs_truth,\
lpips_refined_vs_truth,pareto_vs_exact,pareto_vs_truth,status";

/// A CSV field, quoted when it holds a comma, quote or line break.
fn field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) { format!("\"{}\"", text.replace('"', "\"\"")) } else { text.into() }
}

fn number(value: f64, decimals: usize) -> String {
    if value.is_infinite() {
        if value > 0.0 { "inf".into() } else { "-inf".into() }
    } else if value.is_nan() {
        "nan".into()
    } else {
        format!("{value:.decimals$}")
    }
}

fn metrics_fields(metrics: &ErrorMetrics) -> [String; 3] {
    [number(metrics.psnr_db, 3), number(metrics.ssim, 5), metrics.lpips.map(|v| number(v, 5)).unwrap_or_default()]
}

/// The CSV text of `report`.
pub fn csv_text(report: &BenchReport) -> String {
    let mut text = format!("{CSV_HEADER}\n");
    for (index, outcome) in report.rows.iter().enumerate() {
        let configuration = outcome.configuration();
        let knobs = configuration.knobs;
        let mut fields =
            vec![index.to_string(), configuration.varied.name().into(), field(&knobs.label()), knobs.width.to_string()];
        match outcome {
            RowOutcome::Measured(row) => {
                let t = &row.times;
                fields.push(row.size.height.to_string());
                fields.extend([
                    knobs.input_frames.to_string(),
                    field(&knobs.culling.label()),
                    knobs.precision.name().into(),
                    (knobs.sky == SkyChoice::Render).to_string(),
                    knobs.skips.name().into(),
                    knobs.motion.name().into(),
                ]);
                fields
                    .extend([t.backbone_ms, t.heads_ms, t.assembly_ms, t.raster_ms, t.total_ms].map(|v| number(v, 2)));
                fields.extend([number(row.gaussians_kept, 1), number(row.gaussian_candidates, 1)]);
                fields.push(row.sky_gaussians.to_string());
                fields.extend([row.skipped.motion_frames.to_string(), row.skipped.sky_views.to_string()]);
                fields.extend(metrics_fields(&row.vs_exact));
                fields.extend(metrics_fields(&row.vs_truth));
                match &row.refined {
                    Some(refined) => {
                        fields.push(number(refined.refine_ms, 2));
                        fields.extend(metrics_fields(&refined.vs_truth));
                    }
                    None => fields.extend(std::iter::repeat_n(String::new(), 4)),
                }
                fields.extend([row.pareto_vs_exact.to_string(), row.pareto_vs_truth.to_string(), "measured".into()]);
            }
            RowOutcome::Skipped { reason, .. } => {
                fields.push(String::new());
                fields.extend([
                    knobs.input_frames.to_string(),
                    field(&knobs.culling.label()),
                    knobs.precision.name().into(),
                    (knobs.sky == SkyChoice::Render).to_string(),
                    knobs.skips.name().into(),
                    knobs.motion.name().into(),
                ]);
                fields.extend(std::iter::repeat_n(String::new(), 22));
                fields.push(field(&format!("skipped: {reason}")));
            }
        }
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text
}

/// The notes file: the run's setting and every note.
pub fn notes_text(report: &BenchReport) -> String {
    let mut text = String::new();
    let _ = writeln!(text, "network: {}", report.network);
    let _ = writeln!(text, "device: {}", report.device);
    let _ = writeln!(
        text,
        "target frames: {:?}, cameras: {:?}; reference size {}",
        report.target_frames, report.cameras, report.reference_size
    );
    if !report.truth_meaningful {
        let _ = writeln!(text, "WARNING: untrained network: the errors against ground truth are meaningless");
    }
    for note in &report.notes {
        let _ = writeln!(text, "- {note}");
    }
    text
}

/// A fixed-width table of the measured rows for the terminal.
pub fn table_text(report: &BenchReport) -> String {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "{:<28} {:>9} {:>8} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>10} {:>10} front",
        "configuration",
        "backbone",
        "heads",
        "assembly",
        "raster",
        "total ms",
        "kept/view",
        "dB exact",
        "dB truth",
        "refine ms",
        "dB refined",
    );
    for outcome in &report.rows {
        match outcome {
            RowOutcome::Measured(row) => text.push_str(&table_line(row)),
            RowOutcome::Skipped { configuration, reason } => {
                let _ = writeln!(text, "{:<28} skipped: {reason}", configuration.knobs.label());
            }
        }
    }
    text
}

fn table_line(row: &MeasuredRow) -> String {
    let t = &row.times;
    let front = match (row.pareto_vs_exact, row.pareto_vs_truth) {
        (true, true) => "exact+truth",
        (true, false) => "exact",
        (false, true) => "truth",
        (false, false) => "",
    };
    format!(
        "{:<28} {:>9.1} {:>8.1} {:>9.1} {:>8.1} {:>9.1} {:>9.0} {:>9} {:>9} {:>10} {:>10} {front}\n",
        row.configuration.knobs.label(),
        t.backbone_ms,
        t.heads_ms,
        t.assembly_ms,
        t.raster_ms,
        t.total_ms,
        row.gaussians_kept,
        number(row.vs_exact.psnr_db, 2),
        number(row.vs_truth.psnr_db, 2),
        row.refined.map_or_else(|| "-".into(), |r| number(r.refine_ms, 1)),
        row.refined.map_or_else(|| "-".into(), |r| number(r.vs_truth.psnr_db, 2)),
    )
}

/// Writes `text` to `path`.
pub fn write_text(path: &Path, text: &str) -> Result<(), BenchError> {
    std::fs::write(path, text).map_err(|e| BenchError::file(path, format!("cannot write: {e}")))
}
