//! One sample's training objective: run the network, place the per-pixel Gaussians with the chosen cameras,
//! render every target (and input) view at its time over the sky, and combine the weighted losses.
//!
//! Terms (each averaged over the views that have what it needs):
//! - `rgb_l2`: mean squared error of the final colours;
//! - `lpips`: LPIPS on the renders (the release's train-style input, `[0, 1]` unscaled);
//! - `gram`: Gram-matrix loss of VGG-16 features;
//! - `opacity_bce`: rendered foreground alpha against `1 - sky`;
//! - `dynamic_bce`: dynamic logits of the inputs against their dynamic masks;
//! - `lifespan_l1`: mean `1 / lifespan` over Gaussians predicted static;
//! - `camera`: L1 of every camera-head iteration's encoding against the ground truth (relative to input 0);
//! - `depth`: L1 of log depth against the export's depth;
//! - `rendered_depth`: the same of the target views' rendered expected depth (where drawn);
//! - `flow`: L1 of the predicted velocities against the export's scene flow, moving and still cells weighed
//!   equally;
//! - `learnt_flow`: the same of the flow head's learnt velocities, at the query pixels it moved.

use std::collections::BTreeMap;

use burn::tensor::{FloatDType, Int, Tensor, TensorData};
use dggt_geom::PoseEncoding;
use dggt_infer::{
    CameraSource, InputCameras, MotionPath, RenderSection, SceneOptions, SkyChoice, ViewSlot, forward_chunked,
    input_views,
};
use dggt_losses::{GramLoss, Lpips, bce_with_logits, l2, lifespan_l1, opacity_loss};
use dggt_metrics::psnr;
use dggt_model::Dggt;
use dggt_model::host::host_f32;
use dggt_scene::{AssemblyCounts, Axes, PixelGaussians, Scene4d, TargetView};

use crate::batch::{DepthFlowSamples, StepBatch, ViewTruth};
use crate::error::ObjectiveError;
use crate::weights::{LossTerm, LossWeights};

/// The losses and what they need, built once per run.
pub struct Objective {
    pub weights: LossWeights,
    pub render: RenderSection,
    lpips: Option<Lpips>,
    gram: Option<GramLoss>,
}

/// The result of one sample.
#[derive(Debug, Clone)]
pub struct SampleLoss {
    /// The weighted sum.
    pub total: Tensor<1>,
    /// Each unweighted term, on the host.
    pub terms: BTreeMap<LossTerm, f64>,
    /// Mean PSNR of the target renders (dB).
    pub target_psnr: f64,
    /// Gaussians assembled per rendered view, summed.
    pub counts: AssemblyCounts,
}

/// Which of a batch's views a pass renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewsToRender {
    /// The targets alone (validation).
    Targets,
    /// The targets, then the inputs re-rendered (`render.render_inputs`).
    TargetsAndInputs,
}

impl ViewsToRender {
    /// The views a training step renders under `render`.
    pub fn for_training(render: &RenderSection) -> Self {
        if render.render_inputs { Self::TargetsAndInputs } else { Self::Targets }
    }
}

/// What a forward pass rendered for one view.
pub struct RenderedView {
    pub truth_index: usize,
    pub is_target: bool,
    pub rgb: Tensor<3>,
    pub alpha: Tensor<2>,
    /// `[H, W]` expected depth of the foreground (0 where empty).
    pub depth: Tensor<2>,
    pub counts: AssemblyCounts,
}

impl Objective {
    pub fn new(
        weights: LossWeights,
        render: RenderSection,
        device: &burn::tensor::Device,
    ) -> Result<Self, ObjectiveError> {
        let lpips = match (&weights.lpips_weights, &weights.lpips_backbone) {
            (Some(linear), Some(backbone)) if weights.lpips > 0.0 => {
                Some(Lpips::load(weights.lpips_net, backbone, linear, device)?)
            }
            _ => None,
        };
        let gram = match &weights.gram_backbone {
            Some(path) if weights.gram > 0.0 => Some(GramLoss::load(path, device)?),
            _ => None,
        };
        Ok(Self { weights, render, lpips, gram })
    }

    /// Runs the network on the batch and renders its views (targets, then inputs when configured).
    pub fn render(
        &self,
        model: &Dggt,
        batch: &StepBatch,
        which: ViewsToRender,
    ) -> Result<(Forward, Vec<RenderedView>), ObjectiveError> {
        let forward = Forward::run(model, batch, &self.render)?;
        let views = self.render_views(&forward, batch, which)?;
        Ok((forward, views))
    }

    /// Renders the batch's views (targets, then inputs when asked) from a forward pass's Gaussians.
    pub fn render_views(
        &self,
        forward: &Forward,
        batch: &StepBatch,
        which: ViewsToRender,
    ) -> Result<Vec<RenderedView>, ObjectiveError> {
        let mut wanted: Vec<(usize, bool)> = (0..batch.targets.len()).map(|i| (i, true)).collect();
        if which == ViewsToRender::TargetsAndInputs {
            wanted.extend((0..batch.inputs.len()).map(|i| (i, false)));
        }
        let targets: Vec<TargetView> = wanted
            .iter()
            .map(|&(index, is_target)| {
                let truth = if is_target { &batch.targets[index] } else { &batch.inputs[index] };
                let camera = match self.render.cameras {
                    CameraSource::GroundTruth => truth.camera,
                    CameraSource::Predicted => forward.scene.camera_at(truth.rig_camera, truth.time)?,
                };
                Ok(TargetView { rig_camera: truth.rig_camera, time: truth.time, camera })
            })
            .collect::<Result<_, ObjectiveError>>()?;
        let rendered = forward.scene.render_all(&targets)?;
        Ok(wanted
            .into_iter()
            .zip(rendered)
            .map(|((truth_index, is_target), view)| RenderedView {
                truth_index,
                is_target,
                rgb: view.rgb,
                alpha: view.alpha.squeeze_dim::<2>(0),
                depth: view.depth.squeeze_dim::<2>(0),
                counts: view.counts,
            })
            .collect())
    }

    /// The weighted camera loss alone, from the aggregator and the camera head (no dense head runs, nothing is
    /// rendered): the loss of a pose warm-up step (`optim.pose_warmup_steps`).
    pub fn pose_loss(&self, model: &Dggt, batch: &StepBatch) -> Result<SampleLoss, ObjectiveError> {
        let aggregator = model.aggregator.forward(batch.images.clone())?;
        let last = aggregator.output_list.last().ok_or(ObjectiveError::Unsupported("the aggregator has no layer"))?;
        let camera = model.camera_head.forward(last.clone());
        let encodings: Vec<Tensor<3>> = camera.encodings.iter().map(|e| e.clone().cast(FloatDType::F32)).collect();
        let loss = camera_loss(&encodings, batch)?;
        let terms = BTreeMap::from([(LossTerm::Camera, scalar(&loss)?)]);
        Ok(SampleLoss {
            total: loss.mul_scalar(self.weights.camera),
            terms,
            target_psnr: f64::NAN,
            counts: AssemblyCounts::default(),
        })
    }

    /// The weighted loss of one sample.
    pub fn loss(&self, model: &Dggt, batch: &StepBatch) -> Result<SampleLoss, ObjectiveError> {
        let forward = Forward::run(model, batch, &self.render)?;
        self.loss_of(&forward, batch)
    }

    /// The weighted loss of a forward pass's outputs (from the network, or built by hand) on `batch`.
    pub fn loss_of(&self, forward: &Forward, batch: &StepBatch) -> Result<SampleLoss, ObjectiveError> {
        let w = &self.weights;
        let views = self.render_views(forward, batch, ViewsToRender::for_training(&self.render))?;
        let device = batch.images.device();
        let truth = |view: &RenderedView| -> &ViewTruth {
            if view.is_target { &batch.targets[view.truth_index] } else { &batch.inputs[view.truth_index] }
        };
        let mut terms: BTreeMap<LossTerm, f64> = BTreeMap::new();
        let mut total = Tensor::<1>::zeros([1], &device);
        let mut add = |term: LossTerm, value: Tensor<1>, terms: &mut BTreeMap<LossTerm, f64>| {
            terms.insert(term, scalar(&value)?);
            let weight = term.weight(w);
            if weight > 0.0 {
                total = total.clone() + value.mul_scalar(weight);
            }
            Ok::<(), ObjectiveError>(())
        };

        let rendered = Tensor::stack::<4>(views.iter().map(|v| v.rgb.clone()).collect(), 0);
        let expected = Tensor::stack::<4>(views.iter().map(|v| truth(v).image.clone()).collect(), 0);
        add(LossTerm::RgbL2, l2(rendered.clone(), expected.clone())?, &mut terms)?;
        if let Some(lpips) = &self.lpips {
            add(LossTerm::Lpips, lpips.train_style(rendered.clone(), expected.clone())?.mean(), &mut terms)?;
        }
        if let Some(gram) = &self.gram {
            add(LossTerm::Gram, gram.forward(rendered, expected)?.value.mean(), &mut terms)?;
        }
        let with_sky: Vec<&RenderedView> = views.iter().filter(|v| truth(v).sky.is_some()).collect();
        if w.opacity_bce > 0.0 && !with_sky.is_empty() {
            let alpha = Tensor::stack::<3>(with_sky.iter().map(|v| v.alpha.clone()).collect(), 0);
            let sky = Tensor::stack::<3>(with_sky.iter().map(|v| truth(v).sky.clone().unwrap()).collect(), 0);
            add(LossTerm::OpacityBce, opacity_loss(alpha, sky)?, &mut terms)?;
        }
        if w.dynamic_bce > 0.0
            && let Some(logits) = &forward.dynamic_logit
        {
            let labelled: Vec<usize> = (0..batch.inputs.len()).filter(|&i| batch.inputs[i].dynamic.is_some()).collect();
            if !labelled.is_empty() {
                let frames = logits.clone().squeeze_dim::<3>(0);
                let index = Tensor::<1, Int>::from_data(
                    TensorData::new(labelled.iter().map(|&i| i as i64).collect::<Vec<_>>(), [labelled.len()]),
                    &device,
                );
                let masks =
                    Tensor::stack::<3>(labelled.iter().map(|&i| batch.inputs[i].dynamic.clone().unwrap()).collect(), 0);
                add(LossTerm::DynamicBce, bce_with_logits(frames.select(0, index), masks)?, &mut terms)?;
            }
        }
        if w.lifespan_l1 > 0.0 {
            let lifespan = forward.pixels().lifespan.clone();
            let statics = match &forward.pixels().dynamic_logit {
                Some(logit) => {
                    let values = host_f32(logit.clone(), "dynamic logit")?;
                    let index: Vec<i64> = (0..values.len()).filter(|&i| values[i] < 0.0).map(|i| i as i64).collect();
                    let count = index.len();
                    lifespan.select(0, Tensor::<1, Int>::from_data(TensorData::new(index, [count]), &device))
                }
                None => lifespan,
            };
            if statics.dims()[0] > 0 {
                add(LossTerm::LifespanL1, lifespan_l1(statics)?, &mut terms)?;
            }
        }
        if w.camera > 0.0 {
            add(LossTerm::Camera, camera_loss(&forward.encodings, batch)?, &mut terms)?;
        }
        if w.depth > 0.0
            && let Some(loss) = depth_loss(&forward.depth, batch)?
        {
            add(LossTerm::Depth, loss, &mut terms)?;
        }
        if w.rendered_depth > 0.0 {
            let targets: Vec<(&RenderedView, &DepthFlowSamples)> = views
                .iter()
                .filter(|v| v.is_target)
                .filter_map(|v| truth(v).depth_flow.as_ref().map(|samples| (v, samples)))
                .collect();
            if let Some(loss) = rendered_depth_loss(&targets)? {
                add(LossTerm::RenderedDepth, loss, &mut terms)?;
            }
        }
        if w.flow > 0.0
            && let Some(velocity) = &forward.velocity
            && let Some(loss) = flow_loss(velocity, batch)?
        {
            add(LossTerm::Flow, loss, &mut terms)?;
        }
        if w.learnt_flow > 0.0
            && let Some(loss) = learnt_flow_loss(forward.pixels(), batch)?
        {
            add(LossTerm::LearntFlow, loss, &mut terms)?;
        }

        let mut psnrs = Vec::new();
        let mut counts = AssemblyCounts::default();
        for view in &views {
            counts.candidates += view.counts.candidates;
            counts.transparent += view.counts.transparent;
            counts.off_screen += view.counts.off_screen;
            counts.static_kept += view.counts.static_kept;
            counts.dynamic_kept += view.counts.dynamic_kept;
            if view.is_target {
                psnrs.push(psnr(
                    &host_f32(view.rgb.clone(), "render")?,
                    &host_f32(truth(view).image.clone(), "target image")?,
                )?);
            }
        }
        let target_psnr = if psnrs.is_empty() { f64::NAN } else { psnrs.iter().sum::<f64>() / psnrs.len() as f64 };
        Ok(SampleLoss { total, terms, target_psnr, counts })
    }
}

/// The network's outputs that the losses and the renders read.
pub struct Forward {
    /// The Gaussians placed with the chosen cameras, and the sky.
    pub scene: Scene4d,
    /// `[1, S, H, W]`.
    pub depth: Tensor<4>,
    /// `[1, S, H, W]`.
    pub dynamic_logit: Option<Tensor<4>>,
    /// Every camera-head iteration's `[1, S, 9]` encoding.
    pub encodings: Vec<Tensor<3>>,
    /// `[1, S, H, W, 3]` the predicted velocities (camera axes, world units per log frame), if the network
    /// predicts them.
    pub velocity: Option<Tensor<5>>,
}

impl Forward {
    /// The network on the batch's inputs (one chunk of all frames), its Gaussians placed with the cameras
    /// `render` chooses.
    pub fn run(model: &Dggt, batch: &StepBatch, render: &RenderSection) -> Result<Self, ObjectiveError> {
        let frames = batch.images.dims()[1];
        let prediction = forward_chunked(model, batch.images.clone(), frames, MotionPath::Always)?;
        let cameras = match render.cameras {
            CameraSource::GroundTruth => InputCameras::Given(batch.inputs.iter().map(|v| v.camera).collect()),
            CameraSource::Predicted => InputCameras::Predicted,
        };
        let slots: Vec<ViewSlot> =
            batch.inputs.iter().map(|v| ViewSlot { rig_camera: v.rig_camera, time: v.time }).collect();
        let views = input_views(&prediction, &slots, cameras, batch.size)?;
        let options = SceneOptions {
            means_gradient: render.means_gradient,
            sky: if render.sky { SkyChoice::Render } else { SkyChoice::Skip },
            assembly: render.assembly(),
        };
        let scene = prediction.scene(model, &batch.images, views, &batch.timeline, &options)?.ok_or(
            ObjectiveError::Unsupported(
                "the configuration has no Gaussian head (gs_head); it cannot be trained to render",
            ),
        )?;
        Ok(Self {
            scene,
            depth: prediction.depth,
            dynamic_logit: prediction.dynamic_logit,
            encodings: prediction.encodings,
            velocity: prediction.velocity,
        })
    }

    /// The per-pixel Gaussians.
    pub fn pixels(&self) -> &PixelGaussians {
        &self.scene.pixels
    }
}

/// Mean over iterations of the L1 distance between predicted and ground-truth encodings.
fn camera_loss(encodings: &[Tensor<3>], batch: &StepBatch) -> Result<Tensor<1>, ObjectiveError> {
    let device = batch.images.device();
    let truth: Vec<f32> = batch
        .inputs
        .iter()
        .flat_map(|v| {
            PoseEncoding::encode(&v.camera.world_from_camera.inverse(), &v.camera.intrinsics, batch.size)
                .to_array()
                .map(|x| x as f32)
        })
        .collect();
    let truth = Tensor::<3>::from_data(TensorData::new(truth, [1, batch.inputs.len(), 9]), &device);
    let per_iteration: Vec<Tensor<1>> =
        encodings.iter().map(|e| (e.clone() - truth.clone()).abs().mean().reshape([1])).collect();
    let count = per_iteration.len().max(1) as f64;
    Ok(Tensor::cat(per_iteration, 0).sum().div_scalar(count))
}

/// L1 of log depth at the pixels with a measured depth; `None` when no input view has any.
fn depth_loss(depth: &Tensor<4>, batch: &StepBatch) -> Result<Option<Tensor<1>>, ObjectiveError> {
    let device = depth.device();
    let [_, frames, h, w] = depth.dims();
    let (mut index, mut values) = (Vec::new(), Vec::new());
    for (frame, view) in batch.inputs.iter().enumerate().take(frames) {
        if let Some(samples) = &view.depth_flow {
            index.extend(samples.pixels.iter().map(|&p| p + (frame * h * w) as i64));
            values.extend(samples.depths.iter().map(|d| d.ln()));
        }
    }
    if index.is_empty() {
        return Ok(None);
    }
    let count = index.len();
    let predicted = depth.clone().reshape([frames * h * w]).clamp_min(1e-6).log();
    let picked = predicted.select(0, Tensor::<1, Int>::from_data(TensorData::new(index, [count]), &device));
    let truth = Tensor::<1>::from_data(TensorData::new(values, [count]), &device);
    Ok(Some((picked - truth).abs().mean()))
}

/// L1 of log depth of each view's rendered depth `[H, W]` at its samples where the render drew something (a
/// positive depth); `None` when no such sample exists. The views' depths are read to the host once, together.
fn rendered_depth_loss(views: &[(&RenderedView, &DepthFlowSamples)]) -> Result<Option<Tensor<1>>, ObjectiveError> {
    let Some((first, _)) = views.first() else { return Ok(None) };
    let flat = |view: &RenderedView| {
        let [h, w] = view.depth.dims();
        view.depth.clone().reshape([h * w])
    };
    let all = Tensor::cat(views.iter().map(|(view, _)| flat(view)).collect(), 0);
    let drawn = host_f32(all.clone(), "rendered depth")?;
    let (mut pixels, mut truth) = (Vec::new(), Vec::new());
    let mut offset = 0;
    for (view, samples) in views {
        let [h, w] = view.depth.dims();
        let own = &drawn[offset..offset + h * w];
        for (&p, &d) in samples.pixels.iter().zip(&samples.depths) {
            if own.get(p as usize).is_some_and(|&value| value > 0.0) {
                pixels.push(p + offset as i64);
                truth.push(d.ln());
            }
        }
        offset += h * w;
    }
    if pixels.is_empty() {
        return Ok(None);
    }
    let device = first.depth.device();
    let count = pixels.len();
    let picked = all.select(0, Tensor::<1, Int>::from_data(TensorData::new(pixels, [count]), &device)).log();
    let truth = Tensor::<1>::from_data(TensorData::new(truth, [count]), &device);
    Ok(Some((picked - truth).abs().mean()))
}

/// L1 of the predicted velocities against the export's scene flow at the cells with a measurement: the mean
/// over moving cells plus the mean over still ones, so that the few moving cells of a street weigh as much as
/// its static surfaces (which must not move); `None` when no input view has flow.
fn flow_loss(velocity: &Tensor<5>, batch: &StepBatch) -> Result<Option<Tensor<1>>, ObjectiveError> {
    let [_, frames, h, w, channels] = velocity.dims();
    let cells = FlowCells::of(batch, frames, h * w, |_| true);
    Ok(cells.l1(velocity.clone().reshape([frames * h * w, channels])))
}

/// [`flow_loss`] of the flow head's learnt velocities, at the cells whose pixel the head moved. The learnt
/// velocities (world axes, per unit of scene time) are compared in the flow's units: the view's camera axes
/// (`v_camera = R^T v_world`, `R` = world-from-camera) per log frame. `None` without a learnt flow, without
/// flow at a moved pixel, or for a single-frame timeline.
pub fn learnt_flow_loss(pixels: &PixelGaussians, batch: &StepBatch) -> Result<Option<Tensor<1>>, ObjectiveError> {
    let frames_per_time = batch.timeline.frames_per_time();
    if frames_per_time <= 0.0 {
        return Ok(None);
    }
    let Some(learnt) = pixels.learnt_velocity() else { return Ok(None) };
    let (frames, per_view) = (pixels.views.len(), pixels.size.area());
    let camera = pixels.rotate_rows(learnt.velocity, Axes::WorldToCamera).div_scalar(frames_per_time as f32);
    let cells = FlowCells::of(batch, frames, per_view, |row| learnt.measured[row]);
    // The counts are taken only when the trace is on (tracing evaluates a field when its event is enabled).
    tracing::debug!(
        queries = learnt.measured.iter().filter(|&&m| m).count(),
        cells = cells.rows.len(),
        moving = cells.moving.iter().filter(|&&m| m).count(),
        "learnt flow supervision"
    );
    if tracing::enabled!(tracing::Level::DEBUG) {
        trace_flow_reach(pixels, &cells, frames_per_time)?;
    }
    Ok(cells.l1(camera))
}

/// The neighbours the flow head attends to (the configuration's default `k`), for the reach trace.
const TRACED_NEIGHBOURS: usize = 16;

/// Traces how far the flow head would have to look for the true matches of its moving supervised queries
/// ([`PixelGaussians::flow_reach`]): the export's flow (camera axes per log frame) turned into world axes per unit
/// of scene time.
fn trace_flow_reach(pixels: &PixelGaussians, cells: &FlowCells, frames_per_time: f64) -> Result<(), ObjectiveError> {
    let per_view = pixels.size.area();
    let truths: Vec<(usize, [f32; 3])> = cells
        .rows
        .iter()
        .zip(&cells.velocities)
        .zip(&cells.moving)
        .filter(|&(_, &moving)| moving)
        .map(|((&row, v), _)| {
            let row = row as usize;
            let rotation = pixels.views[row / per_view].camera.world_from_camera.rotation_matrix();
            let camera = dggt_geom::glam::DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            let world = rotation * camera * frames_per_time;
            (row, [world.x as f32, world.y as f32, world.z as f32])
        })
        .collect();
    if let Some(reach) = pixels.flow_reach(&truths, TRACED_NEIGHBOURS)? {
        tracing::debug!(
            rows = reach.rows,
            rank_median = reach.rank_median,
            rank_p90 = reach.rank_p90,
            within_neighbours = reach.within_neighbours,
            displacement_median = reach.displacement_median,
            miss_median = reach.miss_median,
            "learnt flow reach"
        );
    }
    Ok(())
}

/// The export's scene-flow cells of a batch's input views that a flow loss compares.
struct FlowCells {
    /// Row in `[frames x pixels]`.
    rows: Vec<i64>,
    /// Camera axes, world units per log frame.
    velocities: Vec<[f32; 3]>,
    moving: Vec<bool>,
}

impl FlowCells {
    /// The cells of the first `frames` inputs (`per_view` pixels each) at the rows `keep` accepts.
    fn of(batch: &StepBatch, frames: usize, per_view: usize, keep: impl Fn(usize) -> bool) -> Self {
        let mut cells = Self { rows: Vec::new(), velocities: Vec::new(), moving: Vec::new() };
        for (frame, view) in batch.inputs.iter().enumerate().take(frames) {
            if let Some(samples @ DepthFlowSamples { velocities: Some(velocities), .. }) = &view.depth_flow {
                for ((&pixel, velocity), &moving) in samples.pixels.iter().zip(velocities).zip(&samples.moving) {
                    let row = pixel + (frame * per_view) as i64;
                    if keep(row as usize) {
                        cells.rows.push(row);
                        cells.velocities.push(*velocity);
                        cells.moving.push(moving);
                    }
                }
            }
        }
        cells
    }

    /// The mean L1 over moving cells plus the one over still cells of `rows` (`[frames x pixels, 3]`) against
    /// the cells' velocities; `None` without cells.
    fn l1(self, rows: Tensor<2>) -> Option<Tensor<1>> {
        if self.rows.is_empty() {
            return None;
        }
        let device = rows.device();
        let count = self.rows.len();
        let moving_count = self.moving.iter().filter(|&&m| m).count();
        // Each cell's share of the loss, per velocity component.
        let share = |m: bool| {
            let group = if m { moving_count } else { count - moving_count };
            1.0 / (group * 3) as f32
        };
        let shares: Vec<f32> = self.moving.iter().map(|&m| share(m)).collect();
        let picked = rows.select(0, Tensor::<1, Int>::from_data(TensorData::new(self.rows, [count]), &device));
        let values: Vec<f32> = self.velocities.into_iter().flatten().collect();
        let truth = Tensor::<2>::from_data(TensorData::new(values, [count, 3]), &device);
        let shares = Tensor::<2>::from_data(TensorData::new(shares, [count, 1]), &device);
        Some(((picked - truth).abs() * shares).sum())
    }
}

/// A loss value on the host; a failure of the device (out of memory, a lost device) is an error here, where the
/// computation is first waited for.
fn scalar(tensor: &Tensor<1>) -> Result<f64, ObjectiveError> {
    Ok(host_f32(tensor.clone(), "loss")?.first().copied().map(f64::from).unwrap_or(f64::NAN))
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;
    use dggt_geom::glam::{DQuat, DVec3};
    use dggt_geom::{ImageSize, PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
    use dggt_model::gaussian_maps::GaussianMaps;
    use dggt_scene::{InputView, MeansGradient, Timeline};

    use super::*;

    /// A one-view batch of a 2x2 image whose flow samples are `cells`: (pixel, velocity, moving).
    fn batch_with_flow(cells: &[(i64, [f32; 3], bool)], device: &Device) -> StepBatch {
        let view = ViewTruth {
            frame: 0,
            rig_camera: 0,
            time: 0.0,
            camera: PosedCamera {
                world_from_camera: WorldFromCamera::IDENTITY,
                intrinsics: PinholeIntrinsics::new(2.0, 2.0, 1.0, 1.0).unwrap(),
            },
            image: Tensor::zeros([2, 2, 3], device),
            sky: None,
            dynamic: None,
            depth_flow: Some(DepthFlowSamples {
                pixels: cells.iter().map(|c| c.0).collect(),
                depths: vec![1.0; cells.len()],
                velocities: Some(cells.iter().map(|c| c.1).collect()),
                moving: cells.iter().map(|c| c.2).collect(),
            }),
        };
        StepBatch {
            step: 0,
            images: Tensor::zeros([1, 1, 3, 2, 2], device),
            size: ImageSize::new(2, 2).unwrap(),
            timeline: Timeline::new(&[0]).unwrap(),
            inputs: vec![view],
            targets: Vec::new(),
        }
    }

    #[test]
    fn the_rendered_depth_loss_compares_log_depth_where_the_render_drew() {
        let device = Device::flex();
        let samples = DepthFlowSamples {
            pixels: vec![0, 1, 3],
            depths: vec![2.0, 4.0, 8.0],
            velocities: None,
            moving: Vec::new(),
        };
        let view = |depth: [f32; 4]| RenderedView {
            truth_index: 0,
            is_target: true,
            rgb: Tensor::zeros([2, 2, 3], &device),
            alpha: Tensor::ones([2, 2], &device),
            depth: Tensor::from_data(TensorData::new(depth.to_vec(), [2, 2]), &device),
            counts: AssemblyCounts::default(),
        };
        let loss = |depth: [f32; 4]| {
            let rendered = view(depth);
            rendered_depth_loss(&[(&rendered, &samples)]).unwrap().map(|l| scalar(&l).unwrap())
        };
        assert!(loss([2.0, 4.0, 9.0, 8.0]).unwrap().abs() < 1e-6, "the sampled pixels exact: no loss");
        // Twice too deep at every sample: ln 2 each.
        let doubled = loss([4.0, 8.0, 0.0, 16.0]).unwrap();
        assert!((doubled - 2f64.ln()).abs() < 1e-6, "ln 2 per sample, got {doubled}");
        // Pixel 1 left empty: only pixels 0 and 3 count.
        let empty = loss([2.0, 0.0, 0.0, 16.0]).unwrap();
        assert!((empty - 2f64.ln() / 2.0).abs() < 1e-6, "the empty pixel is left out, got {empty}");
        assert_eq!(loss([0.0; 4]), None, "nothing drawn: no term");
        // Two views read together: each view's samples index its own depth.
        let (exact, doubled) = (view([2.0, 4.0, 0.0, 8.0]), view([4.0, 8.0, 0.0, 0.0]));
        let both = rendered_depth_loss(&[(&exact, &samples), (&doubled, &samples)]).unwrap().expect("samples drawn");
        let mean = scalar(&both).unwrap();
        assert!((mean - 2.0 * 2f64.ln() / 5.0).abs() < 1e-6, "five drawn samples, two off by ln 2: {mean}");
    }

    #[test]
    fn the_flow_loss_weighs_moving_and_still_cells_equally() {
        let device = Device::flex();
        // One moving cell (pixel 0) among three still ones.
        let batch = batch_with_flow(
            &[(0, [0.6, 0.0, -0.3], true), (1, [0.0; 3], false), (2, [0.0; 3], false), (3, [0.0; 3], false)],
            &device,
        );
        let loss = |velocity: [[f32; 3]; 4]| {
            let values: Vec<f32> = velocity.iter().flatten().copied().collect();
            let velocity = Tensor::<5>::from_data(TensorData::new(values, [1, 1, 2, 2, 3]), &device);
            scalar(&flow_loss(&velocity, &batch).unwrap().expect("flow samples")).unwrap()
        };
        assert!(loss([[0.6, 0.0, -0.3], [0.0; 3], [0.0; 3], [0.0; 3]]).abs() < 1e-7, "exact flow costs nothing");
        // Predicting no motion costs the moving cell's mean error, 0.3, undiluted by the still cells.
        assert!((loss([[0.0; 3]; 4]) - 0.3).abs() < 1e-6);
        // Moving every still cell by 0.3 per component costs as much as missing the moving cell.
        let drift = [0.3; 3];
        assert!((loss([[0.6, 0.0, -0.3], drift, drift, drift]) - 0.3).abs() < 1e-6);

        let without = StepBatch { inputs: vec![ViewTruth { depth_flow: None, ..batch.inputs[0].clone() }], ..batch };
        let velocity = Tensor::<5>::zeros([1, 1, 2, 2, 3], &device);
        assert!(flow_loss(&velocity, &without).unwrap().is_none(), "no flow, no term");
    }

    /// Two 2x2 views of one camera at log frames 0 and 4, the first turned a quarter about y.
    fn two_views() -> Vec<(PosedCamera, f64)> {
        let turned = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let timeline = Timeline::new(&[0, 4]).unwrap();
        [(turned, 0), (DQuat::IDENTITY, 4)]
            .map(|(rotation, frame)| {
                let world_from_camera = WorldFromCamera::from_rotation_translation(rotation, DVec3::ZERO).unwrap();
                let intrinsics = PinholeIntrinsics::new(2.0, 2.0, 1.0, 1.0).unwrap();
                (PosedCamera { world_from_camera, intrinsics }, timeline.time(frame as f64))
            })
            .to_vec()
    }

    #[test]
    fn the_learnt_flow_loss_compares_in_camera_axes_per_log_frame_at_the_moved_rows() {
        let device = Device::flex();
        let views = two_views();
        let inputs: Vec<InputView> =
            views.iter().map(|&(camera, time)| InputView { rig_camera: 0, time, camera }).collect();
        let maps = GaussianMaps::from_raw(Tensor::zeros([1, 2, 2, 2, 12], &device));
        let depth = Tensor::ones([1, 2, 2, 2], &device);
        let pixels =
            PixelGaussians::new(&maps, depth, None, inputs, MeansGradient::Detached, PixelConvention::Centred).unwrap();
        // View 0 moves rows 0-2 to the next input (row 3 not); view 1 every row back to the previous one.
        let next =
            [[1.0, 2.0, 3.0], [0.5, 0.0, -1.0], [0.0, 4.0, 0.0], [0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]];
        let previous =
            [[0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3], [2.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0; 3], [0.0, 0.0, 3.0]];
        let rows = |values: [[f32; 3]; 8]| Tensor::<2>::from_data(TensorData::new(values.concat(), [8, 3]), &device);
        let pixels = pixels.with_known_learnt_flow(rows(next), rows(previous), None).unwrap();
        // Log frames per unit of scene time, and the step's span in scene time.
        let timeline = Timeline::new(&[0, 4]).unwrap();
        let (frames_per_time, span) = (timeline.frames_per_time(), views[1].1 - views[0].1);
        // By hand: view 0 (turned by R about y, R^T (x, y, z) = (-z, y, x)) from its displacement to the next input,
        // view 1 (the last) from minus its displacement from the previous one; per log frame.
        let per_frame = |v: [f32; 3]| v.map(|c| c / (span * frames_per_time) as f32);
        let expected: Vec<[f32; 3]> = (0..8)
            .map(|row| match row {
                0..4 => per_frame([-next[row][2], next[row][1], next[row][0]]),
                _ => per_frame(previous[row].map(|c| -c)),
            })
            .collect();
        let batch_with = |truth: &dyn Fn(usize) -> [f32; 3]| StepBatch {
            step: 0,
            images: Tensor::zeros([1, 2, 3, 2, 2], &device),
            size: ImageSize::new(2, 2).unwrap(),
            timeline,
            inputs: views
                .iter()
                .enumerate()
                .map(|(frame, &(camera, time))| ViewTruth {
                    frame: 4 * frame,
                    rig_camera: 0,
                    time,
                    camera,
                    image: Tensor::zeros([2, 2, 3], &device),
                    sky: None,
                    dynamic: None,
                    depth_flow: Some(DepthFlowSamples {
                        pixels: (0..4).collect(),
                        depths: vec![1.0; 4],
                        velocities: Some((0..4).map(|p| truth(4 * frame + p as usize)).collect()),
                        moving: vec![true; 4],
                    }),
                })
                .collect(),
            targets: Vec::new(),
        };
        let loss = |batch: &StepBatch| scalar(&learnt_flow_loss(&pixels, batch).unwrap().expect("cells")).unwrap();
        // The exact flow costs nothing; row 3, which the flow did not move, is not compared.
        let exact = batch_with(&|row| if row == 3 { [5.0; 3] } else { expected[row] });
        assert!(loss(&exact).abs() < 1e-6, "{}", loss(&exact));
        // Against no motion: the mean absolute component over the seven moved rows.
        let mean =
            expected.iter().enumerate().filter(|&(r, _)| r != 3).flat_map(|(_, v)| v.map(f32::abs)).sum::<f32>() / 21.0;
        assert!((loss(&batch_with(&|_| [0.0; 3])) - f64::from(mean)).abs() < 1e-6);
    }
}
