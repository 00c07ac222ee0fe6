//! The camera head: iterative refinement of each frame's `absT_quaR_FoV` pose encoding from the last
//! aggregator layer's camera token.
//!
//! `tok = token_norm(camera token)`. Iteration `k` embeds either the learned empty pose (`k = 0`) or the
//! previous accumulated pre-activation encoding (detached), turns it into `shift, scale, gate` with
//! `SiLU -> Linear`, modulates the ORIGINAL `tok`: `x = gate * (adaLN(tok) * (1 + scale) + shift) + tok`
//! (adaLN: LayerNorm without affine), runs the trunk (attention across the frames) and `trunk_norm`, and the
//! pose branch adds a delta to the encoding. Each iteration's encoding is activated: translation and quaternion
//! (xyzw) per their activations, the two FoVs (normally ReLU).

use burn::module::{Module, Param};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::{relu, silu};
use burn::tensor::module::layer_norm;
use burn::tensor::{Device, Tensor};

use crate::block::{Block, BlockConfig};
use crate::config::{CameraHeadConfig, PoseActivation};
use crate::constant::ConstantSite;
use crate::mlp::Mlp;

#[derive(Module, Debug)]
pub struct CameraHead {
    pub token_norm: LayerNorm,
    pub trunk: Vec<Block>,
    pub trunk_norm: LayerNorm,
    pub empty_pose_tokens: Param<Tensor<3>>,
    pub embed_pose: Linear,
    /// `poseLN_modulation.1` in the release checkpoint (index 0 is the parameter-free SiLU).
    pub pose_ln_modulation: Linear,
    pub pose_branch: Mlp,
    adaln_eps: f64,
    num_iterations: usize,
    #[module(skip)]
    activations: [PoseActivation; 3],
}

/// Per-iteration results, each `[B, S, 9]`.
#[derive(Debug, Clone)]
pub struct CameraHeadOutput {
    /// The pose branch's output of each iteration.
    pub deltas: Vec<Tensor<3>>,
    /// The accumulated encoding before activation after each iteration.
    pub preactivations: Vec<Tensor<3>>,
    /// The activated encoding after each iteration; the last is the prediction.
    pub encodings: Vec<Tensor<3>>,
}

impl CameraHeadOutput {
    /// The final `absT_quaR_FoV` encoding, `[B, S, 9]`.
    pub fn pose_encoding(&self) -> Tensor<3> {
        self.encodings.last().expect("at least one iteration").clone()
    }
}

fn activate(x: Tensor<3>, activation: PoseActivation) -> Tensor<3> {
    match activation {
        PoseActivation::Linear => x,
        PoseActivation::Relu => relu(x),
        PoseActivation::Exp => x.exp(),
    }
}

impl CameraHead {
    pub fn new(config: &CameraHeadConfig, device: &Device) -> Self {
        let dim = config.dim_in;
        let norm = || LayerNormConfig::new(dim).with_epsilon(config.block_norm_eps).init(device);
        let block = BlockConfig {
            dim,
            num_heads: config.num_heads,
            mlp_hidden: config.mlp_hidden(),
            norm_eps: config.block_norm_eps,
            qk_norm_eps: None,
        };
        let [_, hidden, target] = config.pose_branch;
        Self {
            token_norm: norm(),
            trunk: (0..config.trunk_depth).map(|_| Block::new(block, device)).collect(),
            trunk_norm: norm(),
            empty_pose_tokens: Initializer::Zeros.init([1, 1, target], device),
            embed_pose: LinearConfig::new(target, dim).init(device),
            pose_ln_modulation: LinearConfig::new(dim, 3 * dim).init(device),
            pose_branch: Mlp::new(dim, hidden, target, device),
            adaln_eps: config.adaln_eps,
            num_iterations: config.num_iterations,
            activations: [config.trans_act, config.quat_act, config.fl_act],
        }
    }

    /// `tokens`: the last aggregator layer, `[B, S, P', dim]`; the camera token is token 0.
    pub fn forward(&self, tokens: Tensor<4>) -> CameraHeadOutput {
        let [b, s, _, dim] = tokens.dims();
        let normed = self.token_norm_out(tokens);
        let ones = ConstantSite::like(&normed).tensor(vec![1.0; dim], [dim]);
        let adaln = layer_norm(normed.clone(), ones, None, self.adaln_eps);
        let target = self.empty_pose_tokens.dims()[2];

        let mut output = CameraHeadOutput { deltas: vec![], preactivations: vec![], encodings: vec![] };
        let mut encoding: Option<Tensor<3>> = None;
        for _ in 0..self.num_iterations {
            let pose_input = match &encoding {
                None => self.empty_pose_tokens.val().expand([b, s, target]),
                Some(previous) => previous.clone().detach(),
            };
            let modulation = self.pose_ln_modulation.forward(silu(self.embed_pose.forward(pose_input)));
            let [shift, scale, gate] = [0, 1, 2].map(|i| modulation.clone().narrow(2, i * dim, dim));
            let mut x = gate * (adaln.clone() * scale.add_scalar(1.0) + shift) + normed.clone();
            for block in &self.trunk {
                x = block.forward(x, None);
            }
            let delta = self.pose_branch.forward(self.trunk_norm.forward(x));
            let accumulated = match encoding {
                None => delta.clone(),
                Some(previous) => previous + delta.clone(),
            };
            output.encodings.push(self.activate_pose(accumulated.clone()));
            output.deltas.push(delta);
            output.preactivations.push(accumulated.clone());
            encoding = Some(accumulated);
        }
        output
    }

    /// `token_norm` of the camera token of `[B, S, P', dim]` tokens, `[B, S, dim]`.
    pub fn token_norm_out(&self, tokens: Tensor<4>) -> Tensor<3> {
        self.token_norm.forward(tokens.narrow(2, 0, 1).squeeze_dim::<3>(2))
    }

    /// Applies the translation, quaternion and field-of-view activations to `[.., 9]` encodings.
    pub fn activate_pose(&self, encoding: Tensor<3>) -> Tensor<3> {
        let [trans, quat, fov] = self.activations;
        Tensor::cat(
            vec![
                activate(encoding.clone().narrow(2, 0, 3), trans),
                activate(encoding.clone().narrow(2, 3, 4), quat),
                activate(encoding.narrow(2, 7, 2), fov),
            ],
            2,
        )
    }
}
