//! `dggt bench`: run time against error for the knobs that trade speed for accuracy in a reconstruction.
//!
//! A sweep ([`knobs`]) is a baseline configuration, the exact reference (the baseline with every culling
//! shortcut off), and one row per other value of each knob — network input width, number of input frames,
//! culling threshold, precision, sky — optionally with the full grid. Each row ([`run`]) times the stages
//! ([`stages`]: backbone, heads, assembly and culling, rasterisation; median of repetitions after a warm-up),
//! counts the Gaussians kept, and measures the error of its target renders against the exact render and
//! against the scene's ground-truth images. The outputs ([`report`], [`plot`]) are `bench.csv`, `bench.png` /
//! `bench.svg` (error against total time with the Pareto front, [`pareto`]) and `bench-notes.txt`.
//!
//! With a diffusion refiner ([`BenchOptions::refine`], `dggt-refine`), every row's renders are also refined:
//! the refinement's time and the refined renders' error against the truth sit beside the unrefined ones.
//!
//! [`compute`] is the other suite (`dggt bench compute`): the network, a training step and the rasteriser at
//! the release's scale, with the reference implementations' figures beside ours; [`refiner`] times the
//! diffusion refiner per frame (`dggt bench refiner`).
//!
//! [`curves`] draws the training curves of runs from their `metrics.jsonl` (`dggt curves`, and the
//! `curves.png` of `dggt train`); it shares the font lookup of the PNG plots with [`plot`].

pub mod compute;
pub mod curves;
mod error;
mod font;
pub mod frames;
pub mod knobs;
pub mod pareto;
pub mod plot;
pub mod precision;
pub mod refiner;
pub mod report;
pub mod run;
pub mod stages;

use std::path::{Path, PathBuf};

pub use curves::{RunCurves, draw_curves};
pub use error::BenchError;
pub use knobs::{Configuration, Culling, Knobs, Precision, Skips, SweepSpec, Varied, parse_motion};
pub use pareto::pareto_front;
pub use run::{BenchOptions, BenchReport, LpipsFiles, MeasuredRow, RefinedRow, RowOutcome, run_bench};

/// The files [`write_outputs`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputFiles {
    pub csv: PathBuf,
    pub png: PathBuf,
    pub svg: PathBuf,
    pub notes: PathBuf,
    /// Whether the PNG has text (a font was found); without one it has points and lines only.
    pub png_has_text: bool,
}

/// Writes `bench.csv`, `bench.png`, `bench.svg` and `bench-notes.txt` into `out` (created if missing).
pub fn write_outputs(report: &BenchReport, out: &Path) -> Result<OutputFiles, BenchError> {
    std::fs::create_dir_all(out).map_err(|e| BenchError::file(out, format!("cannot create the folder: {e}")))?;
    let files = OutputFiles {
        csv: out.join("bench.csv"),
        png: out.join("bench.png"),
        svg: out.join("bench.svg"),
        notes: out.join("bench-notes.txt"),
        png_has_text: false,
    };
    report::write_text(&files.csv, &report::csv_text(report))?;
    let mut notes = report::notes_text(report);
    let png_has_text = plot::write_png(report, &files.png)?;
    if !png_has_text {
        notes.push_str("- bench.png has no text (no font file found); bench.svg has the same plot with labels\n");
    }
    report::write_text(&files.svg, &plot::svg_text(report))?;
    report::write_text(&files.notes, &notes)?;
    Ok(OutputFiles { png_has_text, ..files })
}
