//! Validation: on every validation scene, a fixed set of input frames, and target frames between them rendered
//! and scored with PSNR and SSIM (skimage's definitions), without building a gradient graph; the scores are
//! kept per scene and averaged over scenes. Optionally each target is written as a PNG: the render, the ground
//! truth and their absolute difference (scaled by 4) side by side.

use std::path::Path;
use std::sync::Arc;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_data::{IndexedScene, Preprocess, Scene, TrainingSample, load_sample};
use dggt_losses::image_metrics;
use dggt_model::Dggt;
use dggt_objective::{Objective, StepBatch, ViewsToRender};
use serde::Serialize;

use crate::config::ValidationSection;
use crate::error::TrainError;

/// Scores of one validation pass.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Validation {
    /// Means over the scenes of the per-scene means.
    pub psnr: f64,
    pub ssim: f64,
    /// Per target view of every scene: `(frame, camera, psnr, ssim)`.
    pub views: Vec<(usize, usize, f64, f64)>,
    /// Per scene.
    pub scenes: Vec<SceneScore>,
}

/// One validation scene's scores.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneScore {
    pub scene: String,
    pub psnr: f64,
    pub ssim: f64,
}

/// Scores `model` on every scene of `scenes` at the frames of `frames` (positions in each scene); a scene that
/// fails to load is left out with a warning, and the pass fails only when every scene does. Renders go to
/// `save_to`, in a folder per scene when there are several.
pub fn validate_scenes(
    model: &Dggt,
    objective: &Objective,
    scenes: &[IndexedScene],
    frames: &ValidationSection,
    preprocess: &Preprocess,
    device: &Device,
    save_to: Option<&Path>,
) -> Result<Option<Validation>, TrainError> {
    let needed = frames.inputs.iter().chain(&frames.targets).max().map_or(0, |f| f + 1);
    let (mut scores, mut views, mut last_error) = (Vec::new(), Vec::new(), None);
    for indexed in scenes {
        let folder = save_to.map(|dir| match scenes.len() {
            1 => dir.to_owned(),
            _ => dir.join(indexed.name.replace('/', "_")),
        });
        let scored = indexed.open(0..needed).map_err(TrainError::from).and_then(|scene| {
            let cameras: Vec<usize> = (0..scene.cameras.len()).collect();
            let sample = validation_sample(&frames.inputs, &frames.targets, &cameras);
            validate(model, objective, &Arc::new(scene), preprocess, &sample, device, folder.as_deref())
        });
        match scored {
            Ok(validation) => {
                scores.push(SceneScore { scene: indexed.name.clone(), psnr: validation.psnr, ssim: validation.ssim });
                views.extend(validation.views);
            }
            Err(error) => {
                tracing::warn!(scene = %indexed.name, %error, "validation scene skipped");
                last_error = Some(error);
            }
        }
    }
    if scores.is_empty() {
        return last_error.map_or(Ok(None), Err);
    }
    let count = scores.len() as f64;
    Ok(Some(Validation {
        psnr: scores.iter().map(|s| s.psnr).sum::<f64>() / count,
        ssim: scores.iter().map(|s| s.ssim).sum::<f64>() / count,
        views,
        scenes: scores,
    }))
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
    scene: &Arc<Scene>,
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
    let (psnr, ssim) =
        (metrics.iter().map(|m| m.psnr).sum::<f64>() / count, metrics.iter().map(|m| m.ssim).sum::<f64>() / count);
    Ok(Validation { psnr, ssim, views: per_view, scenes: Vec::new() })
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
