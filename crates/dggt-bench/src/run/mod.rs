//! The sweep: loads the scene and the network once, then measures every configuration: stage times (median of
//! `repeat` runs after `warmup` runs), Gaussians kept, and the error of the target renders against the exact
//! render and against the export's images.
//!
//! Conventions: the world is the first input view's camera frame (ground-truth poses re-expressed in it, as in
//! training, or the camera head's prediction); times in milliseconds; images `[H, W, 3]` RGB in `[0, 1]`
//! (renders clamped to it before any metric, as they are saved); every error is measured at the reference
//! resolution (the baseline width): a render of another size is resized to it, full frame to full frame (each
//! preprocessed size covers the original image's whole field of view), with `image`'s triangle filter
//! (bilinear, widened to an antialiasing filter when shrinking).
//!
//! By phase: `setup` loads what every row shares; per configuration `row` decides whether it runs, `measure`
//! times its repetitions (`prepare` builds their inputs, `repetition` is one timed run), `score` measures its
//! error and `refine` refines its renders; `notes` says what every report must. `options` is what a run is
//! asked, `outcome` what it answers.

mod measure;
mod notes;
mod options;
mod outcome;
mod prepare;
mod refine;
mod repetition;
mod row;
mod score;
mod setup;

use burn::tensor::Device;
use dggt_run::compute_pool::on_pool_worker;

pub use measure::median;
pub use options::{BenchOptions, LpipsFiles};
pub use outcome::{BenchReport, ErrorMetrics, MeasuredRow, RefinedRow, RowOutcome, SkipCounts, StageTimes};
pub use score::resize_rgb;
pub use setup::fresh_tiny_config;

use crate::error::BenchError;

/// Runs the sweep of `options` on `device`, on one of rayon's threads as `dggt reconstruct` and `dggt eval` run
/// ([`on_pool_worker`]), so that its times are theirs.
pub fn run_bench(options: &BenchOptions, device: &Device) -> Result<BenchReport, BenchError> {
    on_pool_worker(|| run_sweep(options, device))
}

/// [`run_bench`] on the calling thread.
fn run_sweep(options: &BenchOptions, device: &Device) -> Result<BenchReport, BenchError> {
    options.sweep.validate()?;
    if options.repeat == 0 {
        return Err(BenchError::setting("--repeat", "must be at least 1"));
    }
    if options.cameras.is_empty() {
        return Err(BenchError::setting("--cameras", "no camera given"));
    }
    let scene = dggt_data::open_scene(&options.scene, None, Some(options.cameras.clone()))?;
    let configurations = options.sweep.configurations();
    let (mut sweep, mut notes) = setup::set_up(options, device, &scene, &configurations)?;
    let mut rows = Vec::new();
    for configuration in configurations {
        rows.push(sweep.row(configuration)?);
    }
    score::mark_pareto(&mut rows);

    notes.extend(notes::standing_notes(options, sweep.reference_size));
    for row in &rows {
        if let RowOutcome::Skipped { configuration, reason } = row {
            notes.push(format!("skipped {}: {reason}", configuration.knobs.label()));
        }
    }
    let network = &sweep.runner.network;
    Ok(BenchReport {
        rows,
        notes,
        reference_size: sweep.reference_size,
        device: format!("{device:?}"),
        network: network.description.clone(),
        truth_meaningful: network.trained,
        target_frames: sweep.runner.plan.targets.clone(),
        cameras: options.cameras.clone(),
        repeat: options.repeat,
        warmup: options.warmup,
    })
}
