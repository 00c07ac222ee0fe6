//! The weight of every loss term, the `[loss]` section of a training configuration, with the files the
//! perceptual terms load.

use std::path::PathBuf;

use dggt_losses::LpipsKind;
use serde::{Deserialize, Serialize};

/// One term of the objective. Declared in the order of their names, so that maps of terms sort as their names
/// do (and sums over them run in that order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LossTerm {
    /// L1 of every camera-head iteration's encoding against the ground truth (relative to input 0).
    Camera,
    /// L1 of log depth against the export's depth.
    Depth,
    /// Dynamic logits of the inputs against their dynamic masks (binary cross-entropy).
    DynamicBce,
    /// L1 of the predicted velocities against the export's scene flow.
    Flow,
    /// Gram-matrix loss of VGG-16 features.
    Gram,
    /// L1 of the flow head's learnt velocities against the export's scene flow.
    LearntFlow,
    /// Mean `1 / lifespan` over Gaussians predicted static.
    LifespanL1,
    /// LPIPS on the renders.
    Lpips,
    /// Rendered foreground alpha against `1 - sky`.
    OpacityBce,
    /// L1 of the target views' rendered log depth against the export's depth.
    RenderedDepth,
    /// Mean squared error of the final colours.
    RgbL2,
}

impl LossTerm {
    pub const ALL: [Self; 11] = [
        Self::Camera,
        Self::Depth,
        Self::DynamicBce,
        Self::Flow,
        Self::Gram,
        Self::LearntFlow,
        Self::LifespanL1,
        Self::Lpips,
        Self::OpacityBce,
        Self::RenderedDepth,
        Self::RgbL2,
    ];

    /// The term's name in configurations and metrics.
    pub fn name(self) -> &'static str {
        match self {
            Self::Camera => "camera",
            Self::Depth => "depth",
            Self::DynamicBce => "dynamic_bce",
            Self::Flow => "flow",
            Self::Gram => "gram",
            Self::LearntFlow => "learnt_flow",
            Self::LifespanL1 => "lifespan_l1",
            Self::Lpips => "lpips",
            Self::OpacityBce => "opacity_bce",
            Self::RenderedDepth => "rendered_depth",
            Self::RgbL2 => "rgb_l2",
        }
    }

    /// The term's weight in `weights`.
    pub fn weight(self, weights: &LossWeights) -> f64 {
        match self {
            Self::Camera => weights.camera,
            Self::Depth => weights.depth,
            Self::DynamicBce => weights.dynamic_bce,
            Self::Flow => weights.flow,
            Self::Gram => weights.gram,
            Self::LearntFlow => weights.learnt_flow,
            Self::LifespanL1 => weights.lifespan_l1,
            Self::Lpips => weights.lpips,
            Self::OpacityBce => weights.opacity_bce,
            Self::RenderedDepth => weights.rendered_depth,
            Self::RgbL2 => weights.rgb_l2,
        }
    }
}

impl std::fmt::Display for LossTerm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for LossTerm {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

/// Weight of every loss term (0 turns a term off). Defaults follow the paper's terms with the release's
/// weights: L2 + LPIPS 0.05 + opacity BCE + dynamic BCE 0.05 + lifespan 0.01.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    /// Mean squared error of the rendered colours.
    pub rgb_l2: f64,
    /// LPIPS (needs `lpips_weights`).
    pub lpips: f64,
    /// The LPIPS backbone: `alex` or `vgg`.
    pub lpips_net: LpipsKind,
    /// The lpips package's linear layers (`alex.pth`/`vgg.pth` or safetensors).
    pub lpips_weights: Option<PathBuf>,
    /// The torchvision backbone (`features.N.*`), `.pth` or safetensors.
    pub lpips_backbone: Option<PathBuf>,
    /// Rendered alpha against 1 - sky mask (binary cross-entropy).
    pub opacity_bce: f64,
    /// Dynamic logits against the dynamic masks of the inputs (binary cross-entropy from logits).
    pub dynamic_bce: f64,
    /// Mean `1 / lifespan` over the static Gaussians.
    pub lifespan_l1: f64,
    /// Gram matrices of VGG-16 features (needs `gram_backbone`).
    pub gram: f64,
    pub gram_backbone: Option<PathBuf>,
    /// Supervision from the export's ground truth, for training from scratch: L1 on the pose encodings of
    /// every camera-head iteration against the poses relative to the first input.
    pub camera: f64,
    /// L1 on log depth against the export's depth maps.
    pub depth: f64,
    /// L1 of log depth against the export's depth maps at the target views, on the rendered expected depth
    /// (what evaluation scores) rather than the network's: through the rasteriser it reaches the Gaussians of
    /// every input that draws there; pixels the render leaves empty are left out.
    pub rendered_depth: f64,
    /// L1 of the predicted velocities against the export's scene flow (`depth_flows_4`), both in the input
    /// camera's axes and world units per log frame, the mean over moving cells plus the mean over still ones;
    /// needs `model.motion_head` or `model.gaussian_velocity`.
    pub flow: f64,
    /// L1 of the flow head's learnt velocities (its displacement to the next input over the time between them)
    /// against the export's scene flow, compared as `flow` is, at the query pixels the head moved (the export's
    /// box flow as optional supervision of the head, which otherwise learns from the renders alone); needs
    /// `model.flow_head`.
    pub learnt_flow: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            rgb_l2: 1.0,
            lpips: 0.05,
            lpips_net: LpipsKind::Alex,
            lpips_weights: None,
            lpips_backbone: None,
            opacity_bce: 0.1,
            dynamic_bce: 0.05,
            lifespan_l1: 0.01,
            gram: 0.0,
            gram_backbone: None,
            camera: 0.0,
            depth: 0.0,
            rendered_depth: 0.0,
            flow: 0.0,
            learnt_flow: 0.0,
        }
    }
}
