//! One forward pass with the DPT heads run a few frames at a time.
//!
//! The aggregator attends across all frames, so it runs once on the whole sequence; the dense heads work on
//! each frame independently, so running them on chunks of frames gives the same maps as
//! [`Dggt::forward`](dggt_model::Dggt::forward) while holding only one chunk's intermediate feature maps at a
//! time. Only what scene building and the losses read is kept: camera encodings, depth, dynamic logits, the
//! Gaussian maps and the velocities. The point and semantic heads, unused by DGGT, are not run; the
//! aggregator's tokens are dropped as soon as the heads are done. Training runs the same pass with one chunk
//! of all frames, under autodiff.
//!
//! The motion head can also be left out where nothing would read it ([`MotionPath::WhereDynamic`]): its
//! velocities only move dynamic Gaussians, and a chunk whose dynamic logits are all too low
//! ([`is_still`]) has none the rasteriser would draw (dynamic opacity `o · sigmoid(logit)` with `o <= 1`
//! stays under its 1/255 threshold), so its velocities are zeros instead and every render is unchanged.

use burn::tensor::{FloatDType, Tensor};
use dggt_model::Dggt;
use dggt_model::aggregator::AggregatorOutput;
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_splat::constants::ALPHA_THRESHOLD;

use crate::error::InferError;

/// The outputs a reconstruction uses, over `S` frames of `H x W`, all `f32` whatever the network computes in.
#[derive(Debug, Clone)]
pub struct Prediction {
    /// Every camera-head iteration's `[1, S, 9]` encoding, the final one last.
    pub encodings: Vec<Tensor<3>>,
    /// `[1, S, H, W]` depth.
    pub depth: Tensor<4>,
    /// `[1, S, H, W]` dynamic logits, when the model has an instance head.
    pub dynamic_logit: Option<Tensor<4>>,
    /// Activated Gaussian maps, when the model has a Gaussian head.
    pub gaussians: Option<GaussianMaps>,
    /// `[1, S, H, W, 3]` velocities ([`Dggt::motion_head`], else the Gaussian head's velocity channels), when
    /// the model predicts motion.
    pub velocity: Option<Tensor<5>>,
    /// Frames whose motion head did not run ([`MotionPath::WhereDynamic`]); their velocities are zeros.
    pub motion_skipped_frames: usize,
    /// The Gaussian head's maps the flow head reads (`ModelConfig::flow_features`), each `[S, C, h, w]` f32;
    /// `None` without a flow head.
    pub flow_features: Option<Vec<Tensor<4>>>,
}

/// Where the motion head runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MotionPath {
    /// On every frame (training: a loss may read the velocities of any pixel).
    #[default]
    Always,
    /// Only on chunks of frames with a pixel the instance head may call dynamic: renders are unchanged.
    WhereDynamic,
}

/// Whether a chunk whose largest dynamic logit is `max_logit` has no dynamic Gaussian the rasteriser would
/// draw: the dynamic opacity is at most `sigmoid(logit)`, which must stay under the alpha threshold (with a
/// relative margin of 1e-3 for the rounding of the tensor sigmoid).
pub fn is_still(max_logit: f32) -> bool {
    let probability = 1.0 / (1.0 + (-f64::from(max_logit)).exp());
    probability < f64::from(ALPHA_THRESHOLD) * (1.0 - 1e-3)
}

impl Prediction {
    /// `[1, S, 9]` the camera head's final encoding.
    pub fn pose_encoding(&self) -> Tensor<3> {
        self.encodings.last().cloned().expect("the camera head runs at least one iteration")
    }
}

/// Runs `model` on `images` (`[1, S, 3, H, W]`, RGB in `[0, 1]`) with the dense heads on `chunk` frames at a
/// time (at least one).
pub fn forward_chunked(
    model: &Dggt,
    images: Tensor<5>,
    chunk: usize,
    motion: MotionPath,
) -> Result<Prediction, InferError> {
    let [batch, ..] = images.dims();
    if batch != 1 {
        return Err(InferError::BatchSize { found: batch });
    }
    let aggregator = model.aggregator.forward(images.clone())?;
    heads_chunked(model, aggregator, images, chunk, motion)
}

/// The camera head and the dense heads on the aggregator's tokens, the dense heads `chunk` frames at a time;
/// `images` are the aggregator's input (the Gaussian head's colour skip reads them). The outputs are `f32`
/// whatever the model's float type; the tokens are dropped once the heads are done.
// Tensors by value, burn's convention (a clone is a handle), as `forward_chunked` passes them on.
#[allow(clippy::needless_pass_by_value)]
pub fn heads_chunked(
    model: &Dggt,
    aggregator: AggregatorOutput,
    images: Tensor<5>,
    chunk: usize,
    motion: MotionPath,
) -> Result<Prediction, InferError> {
    let frames = images.dims()[1];
    let chunk = chunk.max(1);
    let f32 = |t: Tensor<4>| t.cast(FloatDType::F32);
    let last = aggregator.output_list.last().ok_or(InferError::NoAggregatorLayer)?;
    let camera = model.camera_head.forward(last.clone());
    let encodings = camera.encodings.iter().map(|e| e.clone().cast(FloatDType::F32)).collect();
    let (start, grid) = (aggregator.patch_start_idx, aggregator.grid);

    let (mut depth, mut dynamic, mut gaussian_raw, mut velocity) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut flow_features: Vec<Vec<Tensor<4>>> = Vec::new();
    let mut motion_skipped_frames = 0;
    for first in (0..frames).step_by(chunk) {
        let count = chunk.min(frames - first);
        let pick = |tokens: Tensor<4>| tokens.narrow(1, first, count);
        let chunk_images = images.clone().narrow(1, first, count);
        let prediction =
            model.depth_head.predict(|i| pick(aggregator.output_list[i].clone()), start, grid, &chunk_images);
        depth.push(f32(prediction.prediction.narrow(4, 0, 1).squeeze_dim::<4>(4)));
        let mut still = false;
        if let Some(head) = &model.instance_head {
            let prediction = head.predict(|i| pick(aggregator.dino_token_list[i].clone()), start, grid, &chunk_images);
            let logits = f32(prediction.prediction.narrow(4, 0, 1).squeeze_dim::<4>(4));
            // The read-back only where it can save the motion head.
            let skippable = motion == MotionPath::WhereDynamic && model.motion_head.is_some();
            still = skippable && is_still(logits.clone().max().into_scalar());
            dynamic.push(logits);
        }
        if let Some(head) = &model.gs_head {
            let output = head.forward(|i| pick(aggregator.output_with_dino_tokens(i)), start, grid, &chunk_images);
            if model.flow_head.is_some() {
                let maps = output.resized.into_iter().chain([output.head_in]);
                flow_features.push(maps.map(f32).collect());
            }
            let raw = model.apply_color_skip(output.raw, chunk_images.clone());
            gaussian_raw.push(raw.cast(FloatDType::F32));
        }
        if let Some(head) = &model.motion_head {
            if still {
                let [_, _, _, height, width] = chunk_images.dims();
                velocity.push(Tensor::zeros([1, count, height, width, 3], &chunk_images.device()));
                motion_skipped_frames += count;
            } else {
                let prediction = head.predict(|i| pick(aggregator.output_list[i].clone()), start, grid, &chunk_images);
                velocity.push(prediction.prediction.narrow(4, 0, 3).cast(FloatDType::F32));
            }
        }
    }
    drop(aggregator);
    let gaussians = (!gaussian_raw.is_empty()).then(|| GaussianMaps::from_raw(Tensor::cat(gaussian_raw, 1)));
    // The motion head's velocities, else the Gaussian head's velocity channels.
    let velocity = match velocity.is_empty() {
        false => Some(Tensor::cat(velocity, 1)),
        true => gaussians.as_ref().and_then(|maps| maps.velocity.clone()),
    };
    Ok(Prediction {
        encodings,
        depth: Tensor::cat(depth, 1),
        dynamic_logit: (!dynamic.is_empty()).then(|| Tensor::cat(dynamic, 1)),
        gaussians,
        velocity,
        motion_skipped_frames,
        flow_features: concatenated_scales(flow_features),
    })
}

/// Per scale, the chunks' maps joined along the frames; `None` without chunks.
fn concatenated_scales(chunks: Vec<Vec<Tensor<4>>>) -> Option<Vec<Tensor<4>>> {
    let scales = chunks.first()?.len();
    let mut per_scale: Vec<Vec<Tensor<4>>> = vec![Vec::new(); scales];
    for chunk in chunks {
        for (scale, map) in chunk.into_iter().enumerate() {
            per_scale[scale].push(map);
        }
    }
    Some(per_scale.into_iter().map(|maps| Tensor::cat(maps, 0)).collect())
}
