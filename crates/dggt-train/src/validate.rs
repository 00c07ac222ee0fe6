//! Validation: a fixed set of input frames, and target frames between them rendered and scored with PSNR and
//! SSIM (skimage's definitions), without building a gradient graph.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_data::{Preprocess, Scene, TrainingSample, load_sample};
use dggt_losses::image_metrics;
use dggt_model::Dggt;
use serde::Serialize;

use crate::batch::StepBatch;
use crate::error::TrainError;
use crate::objective::Objective;

/// Scores of one validation pass.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Validation {
    pub psnr: f64,
    pub ssim: f64,
    /// Per target view: `(frame, camera, psnr, ssim)`.
    pub views: Vec<(usize, usize, f64, f64)>,
}

/// The validation sample: `inputs` and `targets` frames of every camera in `cameras`.
pub fn validation_sample(inputs: &[usize], targets: &[usize], cameras: &[usize]) -> TrainingSample {
    TrainingSample { input_frames: inputs.to_vec(), target_frames: targets.to_vec(), cameras: cameras.to_vec() }
}

/// Renders the targets of `sample` with `model` (on a device without autodiff) and scores them.
pub fn validate(
    model: &Dggt,
    objective: &Objective,
    scene: &Scene,
    preprocess: &Preprocess,
    sample: &TrainingSample,
    device: &Device,
) -> Result<Validation, TrainError> {
    let loaded = load_sample(scene, preprocess, 0, sample.clone())?;
    let batch = StepBatch::new(&loaded, scene, preprocess, false, device)?;
    let model = model.valid();
    let (_, views) = objective.render(&model, &batch, false)?;
    let rendered = Tensor::stack::<4>(views.iter().map(|v| v.rgb.clone()).collect(), 0);
    let expected = Tensor::stack::<4>(views.iter().map(|v| batch.targets[v.truth_index].image.clone()).collect(), 0);
    let metrics = image_metrics(rendered, expected)?;
    let per_view: Vec<(usize, usize, f64, f64)> = views
        .iter()
        .zip(&metrics)
        .map(|(v, m)| {
            let truth = &batch.targets[v.truth_index];
            (truth.frame, truth.rig_camera, m.psnr, m.ssim)
        })
        .collect();
    let count = metrics.len().max(1) as f64;
    Ok(Validation {
        psnr: metrics.iter().map(|m| m.psnr).sum::<f64>() / count,
        ssim: metrics.iter().map(|m| m.ssim).sum::<f64>() / count,
        views: per_view,
    })
}
