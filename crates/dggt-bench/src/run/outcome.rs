//! What a sweep answers: per configuration a measured row (stage times, Gaussians, errors, Pareto marks,
//! refinement) or the reason it was skipped, and the report around the rows. Plain data, read by the CSV, the
//! plots and the notes.

use dggt_geom::ImageSize;

use crate::knobs::Configuration;

/// Median stage times of one configuration, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    /// Aggregator (patch embedding and alternating attention), timed in a run of its own.
    pub backbone_ms: f64,
    /// Camera head and dense heads (depth, dynamic, Gaussian): a run of the aggregator and the heads together,
    /// less `backbone_ms`.
    pub heads_ms: f64,
    /// Cameras, per-pixel Gaussians, sky Gaussians, and per target view the lifespan fade and culling.
    pub assembly_ms: f64,
    /// Rasterising every target view (foreground and sky), compositing, reading the images back.
    pub raster_ms: f64,
    /// Median of the per-repetition sums of the four.
    pub total_ms: f64,
}

/// Mean over the target views.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorMetrics {
    /// Infinite where the images are identical.
    pub psnr_db: f64,
    pub ssim: f64,
    /// LPIPS-Alex when its weights were given.
    pub lpips: Option<f64>,
}

/// What the row's shortcuts ([`Skips`](crate::knobs::Skips)) left out in its last repetition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SkipCounts {
    /// Input frames whose motion head did not run.
    pub motion_frames: usize,
    /// Target views rendered without their sky (when there is a sky model).
    pub sky_views: usize,
}

/// One measured configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredRow {
    pub configuration: Configuration,
    /// The network's input size.
    pub size: ImageSize,
    /// Input frame positions.
    pub input_frames: Vec<usize>,
    pub times: StageTimes,
    /// Mean over target views of the Gaussians reaching the rasteriser (foreground; the sky's are apart).
    pub gaussians_kept: f64,
    /// Mean over target views of the candidates before culling.
    pub gaussian_candidates: f64,
    pub sky_gaussians: usize,
    pub skipped: SkipCounts,
    pub vs_exact: ErrorMetrics,
    pub vs_truth: ErrorMetrics,
    pub pareto_vs_exact: bool,
    pub pareto_vs_truth: bool,
    /// The renders after the diffusion refiner, when one was given.
    pub refined: Option<RefinedRow>,
}

/// A row's renders refined: the time it took and the error against the ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinedRow {
    /// Median over the repetitions of refining every target view (one frame at a time), milliseconds.
    pub refine_ms: f64,
    pub vs_truth: ErrorMetrics,
}

/// A configuration's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum RowOutcome {
    Measured(MeasuredRow),
    /// Not run: the backend lacks the precision, the scene has too few frames, or the run failed; the reason.
    Skipped {
        configuration: Configuration,
        reason: String,
    },
}

impl RowOutcome {
    pub fn configuration(&self) -> &Configuration {
        match self {
            Self::Measured(row) => &row.configuration,
            Self::Skipped { configuration, .. } => configuration,
        }
    }

    pub fn measured(&self) -> Option<&MeasuredRow> {
        match self {
            Self::Measured(row) => Some(row),
            Self::Skipped { .. } => None,
        }
    }
}

/// The result of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchReport {
    /// One per configuration, in sweep order (the exact reference first).
    pub rows: Vec<RowOutcome>,
    /// Facts a reader needs: what the knobs mean here, what is not swept, what was skipped and why.
    pub notes: Vec<String>,
    /// The size every error is measured at.
    pub reference_size: ImageSize,
    pub device: String,
    /// The checkpoint, or a description of the fresh model.
    pub network: String,
    /// `false` for a fresh model: its ground-truth error means nothing.
    pub truth_meaningful: bool,
    pub target_frames: Vec<usize>,
    pub cameras: Vec<usize>,
    pub repeat: usize,
    pub warmup: usize,
}
