//! The UNet's spatial transformer (diffusers `Transformer2DModel` with linear projections) and its
//! `BasicTransformerBlock`: self-attention, cross-attention to the prompt, GEGLU feed-forward, each
//! pre-LayerNorm and residual.
//!
//! In the reference-view mode ([`ViewAttention::Joint`]) each self-attention runs over the tokens of all views
//! of a sample at once (view 0's tokens first); cross-attention and the feed-forward stay per view.
//!
//! With [`ScorePrecision::Float32`] ("upcast attention") a UNet computing in f16 or bf16 attends in f32.

use burn::module::Module;
use burn::nn::{GroupNorm, LayerNorm, Linear};
use burn::tensor::activation::gelu;
use burn::tensor::{DType, FloatDType, Tensor};
use dggt_model::attention::attend;

use crate::error::RefineError;
use crate::layers::{Bias, group_norm, join_views, layer_norm, linear, split_views};
use crate::weights::Weights;

/// GroupNorm eps before the projection in.
const GROUP_NORM_EPS: f64 = 1e-6;
/// LayerNorm eps inside the blocks.
const LAYER_NORM_EPS: f64 = 1e-5;

/// How self-attention groups the batch rows (`row = sample * views + view`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewAttention {
    /// Every row attends to itself only.
    PerView,
    /// The rows of one sample attend to all of that sample's tokens together.
    Joint { views: usize },
}

impl ViewAttention {
    /// Batch rows per sample.
    pub fn views(self) -> usize {
        match self {
            Self::PerView => 1,
            Self::Joint { views } => views,
        }
    }
}

/// The type attention scores and their softmax are computed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScorePrecision {
    /// The activations' type.
    Native,
    /// f32 whatever the activations' type.
    Float32,
}

/// Sizes of one spatial transformer.
#[derive(Debug, Clone, Copy)]
pub struct TransformerShape {
    pub channels: usize,
    pub heads: usize,
    pub context_dim: usize,
    pub groups: usize,
    pub layers: usize,
    pub scores: ScorePrecision,
}

#[derive(Module, Debug)]
pub struct SpatialTransformer {
    norm: GroupNorm,
    proj_in: Linear,
    blocks: Vec<TransformerBlock>,
    proj_out: Linear,
}

impl SpatialTransformer {
    pub fn load(weights: &mut Weights, prefix: &str, shape: TransformerShape) -> Result<Self, RefineError> {
        let c = shape.channels;
        let blocks = (0..shape.layers)
            .map(|i| TransformerBlock::load(weights, &format!("{prefix}.transformer_blocks.{i}"), shape))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            norm: group_norm(weights, &format!("{prefix}.norm"), shape.groups, c, GROUP_NORM_EPS)?,
            proj_in: linear(weights, &format!("{prefix}.proj_in"), c, c, Bias::With)?,
            blocks,
            proj_out: linear(weights, &format!("{prefix}.proj_out"), c, c, Bias::With)?,
        })
    }

    /// `x`: `[rows, channels, h, w]`; `context`: `[rows, context_tokens, context_dim]`.
    pub fn forward(&self, x: Tensor<4>, context: &Tensor<3>, views: ViewAttention) -> Tensor<4> {
        let [rows, channels, height, width] = x.dims();
        let tokens = self.norm.forward(x.clone()).reshape([rows, channels, height * width]).swap_dims(1, 2);
        let tokens = self.blocks.iter().fold(self.proj_in.forward(tokens), |h, block| block.forward(h, context, views));
        let out = self.proj_out.forward(tokens).swap_dims(1, 2).reshape([rows, channels, height, width]);
        x + out
    }
}

#[derive(Module, Debug)]
struct TransformerBlock {
    norm1: LayerNorm,
    attn1: Attention,
    norm2: LayerNorm,
    attn2: Attention,
    norm3: LayerNorm,
    ff: GegluFeedForward,
}

impl TransformerBlock {
    fn load(weights: &mut Weights, prefix: &str, shape: TransformerShape) -> Result<Self, RefineError> {
        let d = shape.channels;
        let mut norm = |name: &str| layer_norm(weights, &format!("{prefix}.{name}"), d, LAYER_NORM_EPS);
        let (norm1, norm2, norm3) = (norm("norm1")?, norm("norm2")?, norm("norm3")?);
        Ok(Self {
            norm1,
            attn1: Attention::load(weights, &format!("{prefix}.attn1"), d, d, shape)?,
            norm2,
            attn2: Attention::load(weights, &format!("{prefix}.attn2"), d, shape.context_dim, shape)?,
            norm3,
            ff: GegluFeedForward::load(weights, &format!("{prefix}.ff"), d)?,
        })
    }

    fn forward(&self, x: Tensor<3>, context: &Tensor<3>, views: ViewAttention) -> Tensor<3> {
        let normed = self.norm1.forward(x.clone());
        let attended = match views {
            ViewAttention::PerView => self.attn1.forward(normed.clone(), normed),
            ViewAttention::Joint { views } => {
                let joined = join_views(normed, views);
                split_views(self.attn1.forward(joined.clone(), joined), views)
            }
        };
        let x = x + attended;
        let x = x.clone() + self.attn2.forward(self.norm2.forward(x), context.clone());
        x.clone() + self.ff.forward(self.norm3.forward(x))
    }
}

/// Multi-head attention: queries from `x`, keys and values from `context` (the same tensor for
/// self-attention); q/k/v projections without bias, output projection with.
#[derive(Module, Debug)]
struct Attention {
    to_q: Linear,
    to_k: Linear,
    to_v: Linear,
    to_out: Linear,
    heads: usize,
    #[module(skip)]
    scores: ScorePrecision,
}

impl Attention {
    fn load(
        weights: &mut Weights,
        prefix: &str,
        dim: usize,
        context_dim: usize,
        shape: TransformerShape,
    ) -> Result<Self, RefineError> {
        Ok(Self {
            to_q: linear(weights, &format!("{prefix}.to_q"), dim, dim, Bias::Without)?,
            to_k: linear(weights, &format!("{prefix}.to_k"), context_dim, dim, Bias::Without)?,
            to_v: linear(weights, &format!("{prefix}.to_v"), context_dim, dim, Bias::Without)?,
            to_out: linear(weights, &format!("{prefix}.to_out.0"), dim, dim, Bias::With)?,
            heads: shape.heads,
            scores: shape.scores,
        })
    }

    fn forward(&self, x: Tensor<3>, context: Tensor<3>) -> Tensor<3> {
        let [batch, queries, dim] = x.dims();
        let split = |t: Tensor<3>| {
            let [b, n, d] = t.dims();
            t.reshape([b, n, self.heads, d / self.heads]).swap_dims(1, 2)
        };
        let q = split(self.to_q.forward(x));
        let k = split(self.to_k.forward(context.clone()));
        let v = split(self.to_v.forward(context));
        let dtype = q.dtype();
        let out = match self.scores {
            ScorePrecision::Float32 if dtype != DType::F32 => {
                let f32 = |t: Tensor<4>| t.cast(FloatDType::F32);
                attend(f32(q), f32(k), f32(v)).cast(dtype)
            }
            _ => attend(q, k, v),
        };
        let out = out.swap_dims(1, 2).reshape([batch, queries, dim]);
        self.to_out.forward(out)
    }
}

/// `Linear(d, 8d)` split into a value half and a gate half, `value * gelu(gate)` (exact erf GELU),
/// then `Linear(4d, d)`.
#[derive(Module, Debug)]
struct GegluFeedForward {
    proj: Linear,
    out: Linear,
}

impl GegluFeedForward {
    fn load(weights: &mut Weights, prefix: &str, dim: usize) -> Result<Self, RefineError> {
        let inner = 4 * dim;
        Ok(Self {
            proj: linear(weights, &format!("{prefix}.net.0.proj"), dim, 2 * inner, Bias::With)?,
            out: linear(weights, &format!("{prefix}.net.2"), inner, dim, Bias::With)?,
        })
    }

    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let h = self.proj.forward(x);
        let inner = h.dims()[2] / 2;
        let value = h.clone().narrow(2, 0, inner);
        let gate = h.narrow(2, inner, inner);
        self.out.forward(value * gelu(gate))
    }
}
