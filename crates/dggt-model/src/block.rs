//! Pre-norm transformer block with LayerScale: `x += ls1 * attn(norm1(x)); x += ls2 * mlp(norm2(x))`.
//!
//! One type serves the DINO blocks (eps 1e-6, no qk-norm, no RoPE), the aggregator's frame and global blocks
//! (eps 1e-5, qk-norm, RoPE) and the camera-head trunk (eps 1e-5, plain attention).

use burn::module::{Module, Param};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig};
use burn::tensor::{Device, Tensor};

use crate::attention::SelfAttention;
use crate::mlp::Mlp;
use crate::rope::RopeTable;

/// Sizes of one block.
#[derive(Debug, Clone, Copy)]
pub struct BlockConfig {
    pub dim: usize,
    pub num_heads: usize,
    pub mlp_hidden: usize,
    pub norm_eps: f64,
    /// `Some(eps)` enables the per-head q/k LayerNorm.
    pub qk_norm_eps: Option<f64>,
}

/// Per-channel residual scale.
#[derive(Module, Debug)]
pub struct LayerScale {
    pub gamma: Param<Tensor<1>>,
}

impl LayerScale {
    pub fn new(dim: usize, device: &Device) -> Self {
        Self { gamma: Initializer::Ones.init([dim], device) }
    }

    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        x * self.gamma.val().unsqueeze::<D>()
    }
}

#[derive(Module, Debug)]
pub struct Block {
    pub norm1: LayerNorm,
    pub attn: SelfAttention,
    pub ls1: LayerScale,
    pub norm2: LayerNorm,
    pub mlp: Mlp,
    pub ls2: LayerScale,
}

impl Block {
    pub fn new(config: BlockConfig, device: &Device) -> Self {
        let norm = || LayerNormConfig::new(config.dim).with_epsilon(config.norm_eps).init(device);
        Self {
            norm1: norm(),
            attn: SelfAttention::new(config.dim, config.num_heads, config.qk_norm_eps, device),
            ls1: LayerScale::new(config.dim, device),
            norm2: norm(),
            mlp: Mlp::new(config.dim, config.mlp_hidden, config.dim, device),
            ls2: LayerScale::new(config.dim, device),
        }
    }

    /// `x`: `[batch, tokens, dim]`.
    pub fn forward(&self, x: Tensor<3>, rope: Option<&RopeTable>) -> Tensor<3> {
        let x = x.clone() + self.ls1.forward(self.attn.forward(self.norm1.forward(x), rope));
        x.clone() + self.ls2.forward(self.mlp.forward(self.norm2.forward(x)))
    }
}
