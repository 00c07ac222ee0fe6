//! The DGGT network: aggregator, camera head and the DPT heads (depth, point and, for DGGT, Gaussian,
//! instance and semantic) plus DGGT's sky model, with weights loaded from a release checkpoint. Field names are the checkpoint's
//! top-level prefixes.
//!
//! Head inputs, as the release wires them: depth and point heads read `output_list` (2C); the Gaussian head
//! reads `[DINO block 0 | frame_i | global_i]` (3C); the instance and semantic heads read `dino_token_list`
//! (C), at the same tapped layer indices.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, FloatDType, Tensor};
use dggt_flow_head::FlowHead;
use dggt_geom::PixelConvention;

use crate::aggregator::{Aggregator, AggregatorOutput};
use crate::camera_head::{CameraHead, CameraHeadOutput};
use crate::config::{DptHeadConfig, HeadActivation, ModelConfig};
use crate::dpt::{DptHead, DptOutput, DptPrediction};
use crate::error::ModelError;
use crate::gaussian_maps::{GAUSSIAN_CHANNELS, GaussianMaps};
use crate::leaf::CastFloats;
use crate::sky::SkyModel;
use crate::weights::{LoadReport, load_checkpoint};

#[derive(Module, Debug)]
pub struct Dggt {
    pub aggregator: Aggregator,
    pub camera_head: CameraHead,
    pub depth_head: DptHead,
    pub point_head: DptHead,
    /// Activated by [`GaussianMaps`], not by the head's own activations.
    pub gs_head: Option<DptHead>,
    pub instance_head: Option<DptHead>,
    pub semantic_head: Option<DptHead>,
    /// Coloured from the input views with predicted cameras, outside [`Dggt::forward`].
    pub sky_model: Option<SkyModel>,
    /// Velocity of each pixel's Gaussian, in world units per log frame along the axes of the camera that saw
    /// it (OpenCV: x right, y down, z forward); it moves the dynamic Gaussians to a target time. A fresh head
    /// predicts zero (every Gaussian held in place, as without the head).
    pub motion_head: Option<DptHead>,
    /// The learnt scene flow F(ta, tb) between adjacent input times of a camera, from the Gaussian head's
    /// features at the dynamic pixels' Gaussian means (`dggt_scene::PixelGaussians::with_learnt_flow`). A fresh
    /// head predicts zero (every dynamic Gaussian held, as without the head).
    pub flow_head: Option<FlowHead>,
    /// See [`GaussianHeadConfig::color_skip`](crate::config::GaussianHeadConfig::color_skip).
    #[module(skip)]
    pub color_skip: bool,
    /// See [`GaussianHeadConfig::unproject_at`](crate::config::GaussianHeadConfig::unproject_at).
    #[module(skip)]
    pub unproject_at: PixelConvention,
}

/// Input colours are clamped to `[COLOR_SKIP_EPS, 1 - COLOR_SKIP_EPS]` before the logit.
const COLOR_SKIP_EPS: f64 = 1e-3;

/// The Gaussian head's raw output and its activated parameters.
#[derive(Debug, Clone)]
pub struct GaussianOutput {
    pub dpt: DptOutput,
    pub maps: GaussianMaps,
}

/// One forward pass.
#[derive(Debug, Clone)]
pub struct DggtOutput {
    pub aggregator: AggregatorOutput,
    pub camera: CameraHeadOutput,
    /// Depth `[B, S, H, W, 1]` and its confidence.
    pub depth: DptPrediction,
    /// World points `[B, S, H, W, 3]` and their confidence (VGGT's point head; DGGT does not use it); `None`
    /// when not requested.
    pub points: Option<DptPrediction>,
    pub gaussians: Option<GaussianOutput>,
    /// Channel 0 of the prediction is the dynamic logit.
    pub instance: Option<DptPrediction>,
    /// Semantic logits (channels `0..C-1`); DGGT computes but does not use them. `None` when not requested.
    pub semantic: Option<DptPrediction>,
    /// Channels 0-2 of the prediction are the velocity ([`Dggt::motion_head`]); `None` without the head.
    pub motion: Option<DptPrediction>,
}

impl DggtOutput {
    /// `[B, S, H, W, 3]` f32 velocities of the dynamic Gaussians, in world units per log frame along each
    /// view's camera axes: the motion head's, else the Gaussian head's velocity channels; `None` with neither.
    pub fn velocity(&self) -> Option<Tensor<5>> {
        match (&self.motion, &self.gaussians) {
            (Some(motion), _) => Some(motion.prediction.clone().narrow(4, 0, 3).cast(FloatDType::F32)),
            (None, Some(gaussians)) => gaussians.maps.velocity.clone(),
            (None, None) => None,
        }
    }
}

/// Which of the heads nothing downstream of DGGT reads a forward pass computes: each is a full-resolution DPT
/// head, so training and reconstruction skip them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtraHeads {
    /// VGGT's world-point head.
    pub points: bool,
    /// The semantic head.
    pub semantic: bool,
}

impl ExtraHeads {
    /// Every head the network has (as the release's forward computes).
    pub const ALL: Self = Self { points: true, semantic: true };
    /// Only what rendering and the DGGT losses read: cameras, depth, Gaussians, dynamic logits.
    pub const NONE: Self = Self { points: false, semantic: false };
}

impl Dggt {
    /// A network with placeholder parameters (initialised lazily; load weights before use).
    pub fn new(config: &ModelConfig, device: &Device) -> Result<Self, ModelError> {
        config.validate()?;
        Ok(Self {
            aggregator: Aggregator::new(&config.aggregator, device),
            camera_head: CameraHead::new(&config.camera_head, device),
            depth_head: DptHead::new(&config.dpt, &config.depth_head, device),
            point_head: DptHead::new(&config.dpt, &config.point_head, device),
            gs_head: config.gs_head.as_ref().map(|gs| {
                let head = DptHeadConfig {
                    dim_in: gs.dim_in,
                    output_dim: gs.output_dim,
                    activation: HeadActivation::Linear,
                    conf_activation: HeadActivation::Linear,
                };
                let dpt = DptHead::new(&config.dpt, &head, device);
                if gs.velocity { dpt.with_zero_channels(GAUSSIAN_CHANNELS..gs.output_dim) } else { dpt }
            }),
            instance_head: config.instance_head.as_ref().map(|head| DptHead::new(&config.dpt, head, device)),
            semantic_head: config.semantic_head.as_ref().map(|head| DptHead::new(&config.dpt, head, device)),
            sky_model: config.sky_model.as_ref().map(|sky| SkyModel::new(sky, device)),
            motion_head: config
                .motion_head
                .as_ref()
                .map(|head| DptHead::new(&config.dpt, head, device).with_zero_output()),
            flow_head: config
                .flow_head
                .as_ref()
                .map(|head| head.init(device))
                .transpose()
                .map_err(|e| ModelError::Config(format!("flow_head: {e}")))?,
            color_skip: config.gs_head.as_ref().is_some_and(|gs| gs.color_skip),
            unproject_at: config.gs_head.as_ref().map_or(PixelConvention::Integer, |gs| gs.unproject_at),
        })
    }

    /// The network with every float parameter of the aggregator and the heads in `dtype` (f32, f16, bf16).
    ///
    /// Its forward pass then computes in `dtype`: images are cast on entry, constants follow the activations
    /// ([`crate::constant`]), and outputs come out in `dtype` (cast them back before rendering). The sky model
    /// stays f32: it colours host-projected points from the input images and feeds the f32 rasteriser; so does the
    /// flow head, which reads f32 features at f32 Gaussian means.
    pub fn with_float_dtype(self, dtype: FloatDType) -> Self {
        let mut cast = CastFloats(dtype);
        let head = |head: Option<DptHead>, cast: &mut CastFloats| head.map(|head| head.map(cast));
        Self {
            aggregator: self.aggregator.map(&mut cast),
            camera_head: self.camera_head.map(&mut cast),
            depth_head: self.depth_head.map(&mut cast),
            point_head: self.point_head.map(&mut cast),
            gs_head: head(self.gs_head, &mut cast),
            instance_head: head(self.instance_head, &mut cast),
            semantic_head: head(self.semantic_head, &mut cast),
            motion_head: head(self.motion_head, &mut cast),
            ..self
        }
    }

    /// The checkpoint prefixes this network consumes.
    pub fn built_prefixes(&self) -> Vec<&'static str> {
        let optional = [
            ("gs_head.", self.gs_head.is_some()),
            ("instance_head.", self.instance_head.is_some()),
            ("semantic_head.", self.semantic_head.is_some()),
            ("sky_model.", self.sky_model.is_some()),
            ("motion_head.", self.motion_head.is_some()),
            ("flow_head.", self.flow_head.is_some()),
        ];
        ["aggregator.", "camera_head.", "depth_head.", "point_head."]
            .into_iter()
            .chain(optional.into_iter().filter(|(_, built)| *built).map(|(prefix, _)| prefix))
            .collect()
    }

    /// Builds the network and loads a checkpoint with release key names (`.safetensors`, `.pt`, `.pth`).
    pub fn from_checkpoint(
        config: &ModelConfig,
        path: impl AsRef<Path>,
        device: &Device,
    ) -> Result<(Self, LoadReport), ModelError> {
        let mut model = Self::new(config, device)?;
        let report = load_checkpoint(&mut model, path)?;
        Ok((model, report))
    }

    /// `images`: `[B, S, 3, H, W]` RGB in `[0, 1]`. Every head runs.
    pub fn forward(&self, images: Tensor<5>) -> Result<DggtOutput, ModelError> {
        self.forward_with(images, ExtraHeads::ALL)
    }

    /// The Gaussian head's raw output `[B, S, H, W, C]` with the colour skip of `images` (`[B, S, 3, H, W]`, the
    /// same frames) added to its colour channels; unchanged when the model has no colour skip.
    pub fn apply_color_skip(&self, raw: Tensor<5>, images: Tensor<5>) -> Tensor<5> {
        if !self.color_skip {
            return raw;
        }
        // [B, S, 3, H, W] -> [B, S, H, W, 3] logits, in the head's float type.
        let p = images.cast(raw.dtype()).permute([0, 1, 3, 4, 2]).clamp(COLOR_SKIP_EPS, 1.0 - COLOR_SKIP_EPS);
        let logit = (p.clone() / p.neg().add_scalar(1.0)).log();
        let channels = raw.dims()[4];
        Tensor::cat(vec![raw.clone().narrow(4, 0, 3) + logit, raw.narrow(4, 3, channels - 3)], 4)
    }

    /// [`Dggt::forward`] running the point and semantic heads only where `extra` asks.
    // Burn's convention: a forward pass takes its input tensor (a ref-counted handle) by value, as `forward` does.
    #[allow(clippy::needless_pass_by_value)]
    pub fn forward_with(&self, images: Tensor<5>, extra: ExtraHeads) -> Result<DggtOutput, ModelError> {
        let aggregator = self.aggregator.forward(images.clone())?;
        let last = aggregator.output_list.last().expect("aggregator depth is at least one").clone();
        let camera = self.camera_head.forward(last);
        let frame_global = |i: usize| aggregator.output_list[i].clone();
        let dino_tokens = |i: usize| aggregator.dino_token_list[i].clone();
        let (start, grid) = (aggregator.patch_start_idx, aggregator.grid);
        let depth = self.depth_head.predict(frame_global, start, grid, &images);
        let points = extra.points.then(|| self.point_head.predict(frame_global, start, grid, &images));
        let gaussians = self.gs_head.as_ref().map(|head| {
            let dpt = head.forward(|i| aggregator.output_with_dino_tokens(i), start, grid, &images);
            let raw = self.apply_color_skip(dpt.raw.clone(), images.clone());
            // Activated in f32 whatever the network's float type: the maps feed the rasteriser.
            GaussianOutput { maps: GaussianMaps::from_raw(raw.cast(FloatDType::F32)), dpt }
        });
        let instance = self.instance_head.as_ref().map(|head| head.predict(dino_tokens, start, grid, &images));
        let semantic = self
            .semantic_head
            .as_ref()
            .filter(|_| extra.semantic)
            .map(|head| head.predict(dino_tokens, start, grid, &images));
        let motion = self.motion_head.as_ref().map(|head| head.predict(frame_global, start, grid, &images));
        Ok(DggtOutput { aggregator, camera, depth, points, gaussians, instance, semantic, motion })
    }
}
