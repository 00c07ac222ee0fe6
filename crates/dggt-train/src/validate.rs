//! Validation: a fixed set of input frames, and target frames between them rendered and scored with PSNR and
//! SSIM (skimage's definitions), without building a gradient graph. Optionally each target is written as a
//! PNG: the render, the ground truth and their absolute difference (scaled by 4) side by side.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_data::{Preprocess, Scene, TrainingSample, load_sample};
use dggt_losses::image_metrics;
use dggt_model::Dggt;
use dggt_objective::{Objective, StepBatch, ViewsToRender};
use serde::Serialize;

use crate::error::TrainError;

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

/// Renders the targets of `sample` with `model` (on a device without autodiff) and scores them; writes the
/// comparison images into `save_to` when given.
pub fn validate(
    model: &Dggt,
    objective: &Objective,
    scene: &Scene,
    preprocess: &Preprocess,
    sample: &TrainingSample,
    device: &Device,
    save_to: Option<&Path>,
) -> Result<Validation, TrainError> {
    let loaded = load_sample(scene, preprocess, 0, sample.clone())?;
    let batch = StepBatch::new(&loaded, scene, preprocess, false, device)?;
    let model = model.valid();
    let (_, views) = objective.render(&model, &batch, ViewsToRender::Targets)?;
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
    if let Some(dir) = save_to {
        std::fs::create_dir_all(dir).map_err(|source| TrainError::Io { path: dir.into(), source })?;
        for view in &views {
            let truth = &batch.targets[view.truth_index];
            let path = dir.join(format!("frame{:03}_camera{}.png", truth.frame, truth.rig_camera));
            comparison(view.rgb.clone(), truth.image.clone())
                .save(&path)
                .map_err(|e| TrainError::Invalid { what: path.display().to_string(), detail: e.to_string() })?;
        }
    }
    let count = metrics.len().max(1) as f64;
    Ok(Validation {
        psnr: metrics.iter().map(|m| m.psnr).sum::<f64>() / count,
        ssim: metrics.iter().map(|m| m.ssim).sum::<f64>() / count,
        views: per_view,
    })
}

/// `[H, W, 3]` render and truth in `[0, 1]` as one RGB image: render | truth | 4 |render - truth|.
fn comparison(rendered: Tensor<3>, truth: Tensor<3>) -> image::RgbImage {
    let [h, w, _] = rendered.dims();
    let pixels = |t: Tensor<3>| t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
    let (rendered, truth) = (pixels(rendered), pixels(truth));
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    image::RgbImage::from_fn(3 * w as u32, h as u32, |x, y| {
        let (panel, x) = (x as usize / w, x as usize % w);
        let at = (y as usize * w + x) * 3;
        image::Rgb(std::array::from_fn(|k| match panel {
            0 => byte(rendered[at + k]),
            1 => byte(truth[at + k]),
            _ => byte(4.0 * (rendered[at + k] - truth[at + k]).abs()),
        }))
    })
}
