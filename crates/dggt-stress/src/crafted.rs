//! Stress cases that bypass the network: hand-made head outputs at the extremes the activations and the
//! renderer must survive (opacities at 0 and 1, lifespans near 0 and huge, degenerate, huge and anisotropic
//! scales, zero quaternions, saturated colours, depths at 0 and 1e6, empty and all-dynamic frames, all-sky and
//! no-sky views, moderate, huge and non-finite motion-head velocities, objects moved along their trajectories
//! and dynamic Gaussians moved along a flow head's learnt flow among all of these), pushed through the Gaussian
//! activations, placement, rendering, every loss and the backward pass to the hand-made outputs.
//!
//! The raw head output is `[1, S, H, W, 12]`: RGB logits (0-2), opacity logit (3), scale pre-softplus (4-6),
//! rotation `w x y z` before normalisation (7-10), lifespan pre-activation (11), as the Gaussian head emits it.

use std::ops::Range;

use burn::nn::{Linear, LinearConfig};
use burn::tensor::{Device, Tensor, TensorData};
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape};
use dggt_geom::PixelConvention;
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_model::seeded::with_seed;
use dggt_model::sky::SkyModel;
use dggt_objective::{Forward, Objective};
use dggt_scene::{AssemblySettings, DynamicMotion, InputView, MeansGradient, PixelGaussians, Scene4d};

use crate::error::StressError;
use crate::pipeline::{probe_gradient, render_and_differentiate};
use crate::probe::{Probe, Stage};
use crate::scenario::Scenario;
use dggt_data::random::SplitMix64;

/// Channels of the raw Gaussian head output.
pub const RAW_CHANNELS: usize = 12;
pub const RGB: Range<usize> = 0..3;
pub const OPACITY: Range<usize> = 3..4;
pub const SCALE: Range<usize> = 4..7;
pub const ROTATION: Range<usize> = 7..11;
pub const LIFESPAN: Range<usize> = 11..12;

/// A hand-made prediction for the input views of a [`Scenario`], on the host.
#[derive(Debug, Clone)]
pub struct Prediction {
    /// `[S, H, W, 12]` raw Gaussian head output.
    pub raw: Vec<f32>,
    /// `[S, H, W]` depth along the optical axis.
    pub depth: Vec<f32>,
    /// `[S, H, W]` dynamic logits.
    pub dynamic_logit: Vec<f32>,
    /// `[S, H, W, 3]` motion-head velocities (world units per log frame, camera axes); `None`: no motion head.
    pub velocity: Option<Vec<f32>>,
    /// How the dynamic Gaussians reach the targets' times (with `Instances`, the objects among them are found
    /// and moved along their trajectories; with `Learnt`, a flow head runs on [`Self::flow`]).
    pub motion: DynamicMotion,
    /// What the flow head of a `Learnt` motion reads and how far it moves the Gaussians.
    pub flow: LearntFlowInput,
}

/// A flow head's input for the learnt motion: full-resolution features and the gain of its last layer.
#[derive(Debug, Clone)]
pub struct LearntFlowInput {
    /// `[S, FLOW_CHANNELS, H, W]` the features the head reads at the query and target pixels.
    pub features: Vec<f32>,
    /// The head's last layer is a random one times this (a fresh head's is zero and would move nothing).
    pub gain: f32,
}

/// Channels of the crafted flow features.
pub const FLOW_CHANNELS: usize = 4;

impl Prediction {
    /// Moderate random values: what a network might output.
    pub fn random(scenario: &Scenario, seed: u64) -> Self {
        let pixels = scenario.input_frames.len() * scenario.size.area();
        let mut random = SplitMix64::new(seed);
        let raw = (0..pixels * RAW_CHANNELS)
            .map(|i| match i % RAW_CHANNELS {
                3 => random.range(-1.0, 3.0),
                _ => random.range(-1.0, 1.0),
            })
            .collect();
        let depth = (0..pixels).map(|_| random.range(2.0, 30.0)).collect();
        let dynamic_logit = (0..pixels).map(|_| random.range(-4.0, 4.0)).collect();
        let features = (0..pixels * FLOW_CHANNELS).map(|_| random.range(-1.0, 1.0)).collect();
        let flow = LearntFlowInput { features, gain: 1.0 };
        Self { raw, depth, dynamic_logit, velocity: None, motion: DynamicMotion::Velocity, flow }
    }

    /// Gives the prediction motion-head velocities of `magnitude` in random directions.
    pub fn set_velocity(&mut self, magnitude: f32, random: &mut SplitMix64) {
        let count = self.depth.len() * 3;
        self.velocity = Some((0..count).map(|_| magnitude * random.range(-1.0, 1.0)).collect());
    }

    /// Sets `channels` of every pixel to `value`.
    pub fn set_channels(&mut self, channels: Range<usize>, value: f32) {
        for pixel in self.raw.chunks_exact_mut(RAW_CHANNELS) {
            pixel[channels.clone()].fill(value);
        }
    }

    /// Sets `channels` of every pixel to values drawn from `choices`.
    pub fn scatter_channels(&mut self, channels: Range<usize>, choices: &[f32], random: &mut SplitMix64) {
        for pixel in self.raw.chunks_exact_mut(RAW_CHANNELS) {
            for value in &mut pixel[channels.clone()] {
                *value = random.pick(choices);
            }
        }
    }
}

/// Runs a hand-made prediction through placement, rendering, the objective and the backward pass.
pub fn run(
    probe: &mut Probe,
    scenario: &Scenario,
    prediction: &Prediction,
    objective: &Objective,
    sky_model: &SkyModel,
    device: &Device,
) -> Result<(), StressError> {
    let frames = scenario.input_frames.len();
    let (width, height) = (scenario.size.width as usize, scenario.size.height as usize);
    let batch = scenario.batch(device);
    let raw = Tensor::<5>::from_data(
        TensorData::new(prediction.raw.clone(), [1, frames, height, width, RAW_CHANNELS]),
        device,
    )
    .require_grad();
    let map = |values: &[f32]| {
        Tensor::<4>::from_data(TensorData::new(values.to_vec(), [1, frames, height, width]), device).require_grad()
    };
    let (depth, logit) = (map(&prediction.depth), map(&prediction.dynamic_logit));
    let maps = GaussianMaps::from_raw(raw.clone());
    let views: Vec<InputView> =
        batch.inputs.iter().map(|v| InputView { rig_camera: v.rig_camera, time: v.time, camera: v.camera }).collect();
    let pixels = PixelGaussians::new(
        &maps,
        depth.clone(),
        Some(logit.clone()),
        views,
        MeansGradient::Through,
        PixelConvention::Integer,
    )?;
    let velocity = prediction.velocity.as_ref().map(|values| {
        Tensor::<5>::from_data(TensorData::new(values.clone(), [1, frames, height, width, 3]), device).require_grad()
    });
    let pixels = match &velocity {
        Some(velocity) => pixels.with_motion(velocity.clone(), batch.timeline.frames_per_time())?,
        None => pixels,
    };
    let assembly = AssemblySettings { dynamic_motion: prediction.motion, ..objective.render.assembly() };
    let features = Tensor::<4>::from_data(
        TensorData::new(prediction.flow.features.clone(), [frames, FLOW_CHANNELS, height, width]),
        device,
    )
    .require_grad();
    let pixels = match prediction.motion {
        DynamicMotion::Instances => pixels.with_instances(&assembly.instances)?,
        DynamicMotion::Learnt => {
            pixels.with_learnt_flow(&flow_head(prediction.flow.gain, device), std::slice::from_ref(&features))?
        }
        DynamicMotion::Velocity | DynamicMotion::Held => pixels,
    };
    let cameras: Vec<_> =
        batch.inputs.iter().map(|v| (v.camera.world_from_camera.inverse(), v.camera.intrinsics)).collect();
    let images = batch.images.clone().reshape([frames, 3, height, width]);
    let sky = Some(sky_model.gaussians(images, &cameras));
    let scene = Scene4d { pixels, sky, assembly };
    let forward = Forward {
        scene,
        depth: depth.clone(),
        dynamic_logit: Some(logit.clone()),
        encodings: vec![],
        velocity: velocity.clone(),
    };
    let grads = render_and_differentiate(probe, objective, &forward, &batch)?;
    probe_gradient(probe, &grads, "raw Gaussian head output", &raw);
    probe_gradient(probe, &grads, "depth", &depth);
    probe_gradient(probe, &grads, "dynamic logits", &logit);
    // Checked where it exists; not required, since velocities that carry every dynamic Gaussian out of view
    // (or targets at the inputs' own times) rightly leave them without one.
    if let Some(grad) = velocity.as_ref().and_then(|velocity| velocity.grad(&grads)) {
        probe.tensor(Stage::Gradients, "grad velocities", &grad);
    }
    if let Some(grad) = features.grad(&grads) {
        probe.tensor(Stage::Gradients, "grad flow features", &grad);
    }
    Ok(())
}

/// A small flow head reading [`FLOW_CHANNELS`] features, the same for every case, whose last layer is a random
/// one times `gain`.
fn flow_head(gain: f32, device: &Device) -> FlowHead {
    let shape = FlowHeadShape { hidden: 16, heads: 2, neighbours: 8, iterations: 2, ..FlowHeadShape::default() };
    let config = FlowHeadConfig { feature_widths: vec![FLOW_CHANNELS], shape };
    let mut head = with_seed(device, 7, || config.init(device)).expect("a valid flow head configuration");
    let last = with_seed(device, 8, || LinearConfig::new(16, 3).init(device));
    head.update.fc2 = Linear { weight: last.weight.map(|w| w.mul_scalar(gain)), bias: last.bias };
    head
}
