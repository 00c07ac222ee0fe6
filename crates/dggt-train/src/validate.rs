//! Validation: on every validation scene, a fixed set of input frames, and target frames between them rendered
//! without building a gradient graph and scored with PSNR and SSIM (skimage's definitions), LPIPS (AlexNet, the
//! evaluation's `[-1, 1]` input, when weights are configured) and D-RMSE (the rendered expected depth against
//! the export's depth cells, `depth_flows_4` or projected lidar, after the least-squares scale and shift, as
//! `dggt eval` computes it). The scores are kept per view and per scene and averaged over scenes. Optionally
//! each target is written as a PNG: the render, the ground truth and their absolute difference (scaled by 4)
//! side by side.

use std::path::Path;
use std::sync::Arc;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_data::{IndexedScene, LoadedSample, Preprocess, Scene, TrainingSample, load_sample};
use dggt_geom::ImageSize;
use dggt_losses::Lpips;
use dggt_metrics::{MetricError, aligned_depth_rmse, image_metrics};
use dggt_model::Dggt;
use dggt_model::host::host_f32;
use dggt_objective::{DepthFlowMaps, Objective, RenderedView, StepBatch, ViewsToRender, depth_flow_samples};
use serde::Serialize;

use crate::config::ValidationSection;
use crate::error::TrainError;
use crate::snapshot::{SnapshotOptions, ValidationSnapshot, difference_image, rgb_image};

/// Scores of one validation pass.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Validation {
    /// Means over the scenes of the per-scene means (LPIPS and D-RMSE over the scenes that have them).
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub d_rmse: Option<f64>,
    /// Per target view of every scene.
    pub views: Vec<ViewScore>,
    /// Per scene.
    pub scenes: Vec<SceneScore>,
    /// The first scene pictured for a watcher, when the validator was asked to ([`Validator::snapshot`]).
    #[serde(skip)]
    pub snapshot: Option<Arc<ValidationSnapshot>>,
}

/// One target view's scores.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViewScore {
    /// Position in the scene's frames and cameras.
    pub frame: usize,
    pub camera: usize,
    pub psnr: f64,
    pub ssim: f64,
    /// `None` without LPIPS weights.
    pub lpips: Option<f64>,
    /// `None` when the view has no depth cell inside the render.
    pub d_rmse: Option<f64>,
}

/// One validation scene's scores: means over its target views.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneScore {
    pub scene: String,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub d_rmse: Option<f64>,
}

impl Validation {
    /// `PSNR 24.10 dB, SSIM 0.8123, LPIPS 0.1200, D-RMSE 1.2345`: the means it has.
    pub fn scores_line(&self) -> String {
        scores_line(self.psnr, self.ssim, self.lpips, self.d_rmse)
    }
}

impl SceneScore {
    /// The scene's means, as [`Validation::scores_line`] writes them.
    pub fn scores_line(&self) -> String {
        scores_line(self.psnr, self.ssim, self.lpips, self.d_rmse)
    }
}

fn scores_line(psnr: f64, ssim: f64, lpips: Option<f64>, d_rmse: Option<f64>) -> String {
    let optional = |name: &str, value: Option<f64>| value.map_or(String::new(), |v| format!(", {name} {v:.4}"));
    format!("PSNR {psnr:.2} dB, SSIM {ssim:.4}{}{}", optional("LPIPS", lpips), optional("D-RMSE", d_rmse))
}

/// What a validation pass runs with.
pub struct Validator<'a> {
    /// The network, on `device`.
    pub model: &'a Dggt,
    pub objective: &'a Objective,
    /// LPIPS (AlexNet) for the metric, when configured.
    pub lpips: Option<&'a Lpips>,
    pub preprocess: &'a Preprocess,
    /// A device without autodiff.
    pub device: &'a Device,
    /// Picture the first scene for a watcher ([`crate::snapshot`]), and how.
    pub snapshot: Option<SnapshotOptions>,
}

impl Validator<'_> {
    /// Scores every scene of `scenes` at the frames of `frames` (positions in each scene); a scene that fails
    /// to load is left out with a warning, and the pass fails only when every scene does. Renders go to
    /// `save_to`, in a folder per scene when there are several.
    pub fn scenes(
        &self,
        scenes: &[IndexedScene],
        frames: &ValidationSection,
        save_to: Option<&Path>,
    ) -> Result<Option<Validation>, TrainError> {
        let needed = frames.inputs.iter().chain(&frames.targets).max().map_or(0, |f| f + 1);
        let (mut scores, mut views, mut last_error, mut snapshot) = (Vec::new(), Vec::new(), None, None);
        for indexed in scenes {
            let folder = save_to.map(|dir| match scenes.len() {
                1 => dir.to_owned(),
                _ => dir.join(indexed.name.replace('/', "_")),
            });
            let pictured =
                if snapshot.is_none() { self.snapshot.map(|options| (indexed.name.as_str(), options)) } else { None };
            let scored = indexed.open(0..needed).map_err(TrainError::from).and_then(|scene| {
                let cameras: Vec<usize> = (0..scene.cameras.len()).collect();
                let sample = validation_sample(&frames.inputs, &frames.targets, &cameras);
                self.scene_pictured(&Arc::new(scene), &sample, folder.as_deref(), pictured)
            });
            match scored {
                Ok(validation) => {
                    scores.push(SceneScore { scene: indexed.name.clone(), ..scene_score(&validation.views) });
                    views.extend(validation.views);
                    snapshot = snapshot.or(validation.snapshot);
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
        Ok(Some(Validation {
            psnr: mean(scores.iter().map(|s| Some(s.psnr))).unwrap_or(f64::NAN),
            ssim: mean(scores.iter().map(|s| Some(s.ssim))).unwrap_or(f64::NAN),
            lpips: mean(scores.iter().map(|s| s.lpips)),
            d_rmse: mean(scores.iter().map(|s| s.d_rmse)),
            views,
            scenes: scores,
            snapshot,
        }))
    }

    /// Renders the targets of `sample` and scores them; writes the comparison images into `save_to` when
    /// given. The result's `scenes` is empty.
    pub fn scene(
        &self,
        scene: &Arc<Scene>,
        sample: &TrainingSample,
        save_to: Option<&Path>,
    ) -> Result<Validation, TrainError> {
        self.scene_pictured(scene, sample, save_to, None)
    }

    /// [`Validator::scene`], pictured for a watcher as `pictured` says (the scene's name and how).
    fn scene_pictured(
        &self,
        scene: &Arc<Scene>,
        sample: &TrainingSample,
        save_to: Option<&Path>,
        pictured: Option<(&str, SnapshotOptions)>,
    ) -> Result<Validation, TrainError> {
        let loaded = load_sample(scene, self.preprocess, 0, sample.clone())?;
        let batch = StepBatch::new(&loaded, scene, self.preprocess, DepthFlowMaps::Skip, self.device)?;
        let model = self.model.valid();
        let (forward, views) = self.objective.render(&model, &batch, ViewsToRender::Targets)?;
        let snapshot = match pictured {
            Some((name, options)) => Some(Arc::new(ValidationSnapshot::new(name, &forward, &views, &batch, options)?)),
            None => None,
        };
        let rendered = Tensor::stack::<4>(views.iter().map(|v| v.rgb.clone()).collect(), 0);
        let expected =
            Tensor::stack::<4>(views.iter().map(|v| batch.targets[v.truth_index].image.clone()).collect(), 0);
        let lpips = match self.lpips {
            Some(lpips) => Some(host_f32(lpips.eval(rendered.clone(), expected.clone())?, "LPIPS")?),
            None => None,
        };
        let metrics = image_metrics(rendered, expected)?;
        let mut scores = Vec::with_capacity(views.len());
        for (i, (view, m)) in views.iter().zip(&metrics).enumerate() {
            let truth = &batch.targets[view.truth_index];
            scores.push(ViewScore {
                frame: truth.frame,
                camera: truth.rig_camera,
                psnr: m.psnr,
                ssim: m.ssim,
                lpips: lpips.as_ref().map(|values| f64::from(values[i])),
                d_rmse: self.depth_rmse(scene, &loaded, view)?,
            });
        }
        if let Some(dir) = save_to {
            save_comparisons(dir, &views, &batch)?;
        }
        let score = scene_score(&scores);
        Ok(Validation {
            psnr: score.psnr,
            ssim: score.ssim,
            lpips: score.lpips,
            d_rmse: score.d_rmse,
            views: scores,
            scenes: Vec::new(),
            snapshot,
        })
    }

    /// D-RMSE of a rendered target against the export's depth cells of its view; `None` without cells.
    fn depth_rmse(&self, scene: &Scene, loaded: &LoadedSample, view: &RenderedView) -> Result<Option<f64>, TrainError> {
        let target = &loaded.targets[view.truth_index];
        let Some(cells) = depth_flow_samples(scene, self.preprocess, target)? else { return Ok(None) };
        let rendered = host_f32(view.depth.clone(), "rendered depth")?;
        let predicted: Vec<f32> = cells.pixels.iter().map(|&p| rendered[p as usize]).collect();
        match aligned_depth_rmse(&predicted, &cells.depths) {
            Ok(alignment) => Ok(Some(alignment.rmse)),
            Err(MetricError::Empty { .. }) => Ok(None),
            Err(error) => Err(TrainError::DepthScore(error)),
        }
    }
}

/// The validation sample: `inputs` and `targets` frames of every camera in `cameras`.
pub fn validation_sample(inputs: &[usize], targets: &[usize], cameras: &[usize]) -> TrainingSample {
    TrainingSample { input_frames: inputs.to_vec(), target_frames: targets.to_vec(), cameras: cameras.to_vec() }
}

/// The mean of the present values; `None` when none is.
fn mean(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let present: Vec<f64> = values.flatten().collect();
    (!present.is_empty()).then(|| present.iter().sum::<f64>() / present.len() as f64)
}

/// Means over a scene's views (its name left empty).
fn scene_score(views: &[ViewScore]) -> SceneScore {
    SceneScore {
        scene: String::new(),
        psnr: mean(views.iter().map(|v| Some(v.psnr))).unwrap_or(f64::NAN),
        ssim: mean(views.iter().map(|v| Some(v.ssim))).unwrap_or(f64::NAN),
        lpips: mean(views.iter().map(|v| v.lpips)),
        d_rmse: mean(views.iter().map(|v| v.d_rmse)),
    }
}

/// Writes every target's render, truth and difference into `dir`.
fn save_comparisons(dir: &Path, views: &[RenderedView], batch: &StepBatch) -> Result<(), TrainError> {
    std::fs::create_dir_all(dir).map_err(|source| TrainError::Io { path: dir.into(), source })?;
    for view in views {
        let truth = &batch.targets[view.truth_index];
        let path = dir.join(format!("frame{:03}_camera{}.png", truth.frame, truth.rig_camera));
        comparison(view.rgb.clone(), truth.image.clone())?
            .save(&path)
            .map_err(|e| TrainError::Comparison { path: path.clone(), detail: e.to_string() })?;
    }
    Ok(())
}

/// `[H, W, 3]` render and truth in `[0, 1]` as one RGB image: render | truth | 4 |render - truth|.
fn comparison(rendered: Tensor<3>, truth: Tensor<3>) -> Result<image::RgbImage, TrainError> {
    let [h, w, _] = rendered.dims();
    let size = ImageSize { width: w as u32, height: h as u32 };
    let (rendered, truth) = (host_f32(rendered, "validation render")?, host_f32(truth, "validation truth")?);
    let panels = [
        rgb_image(size, &rendered, "validation render")?,
        rgb_image(size, &truth, "validation truth")?,
        difference_image(size, &rendered, &truth)?,
    ];
    let mut joined = image::RgbImage::new(3 * size.width, size.height);
    for (k, panel) in panels.iter().enumerate() {
        image::imageops::replace(&mut joined, panel, i64::from(k as u32 * size.width), 0);
    }
    Ok(joined)
}
