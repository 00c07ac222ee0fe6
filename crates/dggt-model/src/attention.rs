//! Multi-head self-attention with a fused qkv projection, optional per-head q/k LayerNorm (qk-norm) and
//! optional 2D RoPE, as the DINO, aggregator and camera-trunk blocks use it.
//!
//! Order: `qkv` -> split heads -> `q_norm`/`k_norm` over head_dim -> RoPE on q and k ->
//! `softmax(q k^T / sqrt(head_dim)) v` -> merge heads -> `proj`.

use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Device, Tensor};

use crate::rope::RopeTable;

#[derive(Module, Debug)]
pub struct SelfAttention {
    pub qkv: Linear,
    pub q_norm: Option<LayerNorm>,
    pub k_norm: Option<LayerNorm>,
    pub proj: Linear,
    num_heads: usize,
}

impl SelfAttention {
    /// `qk_norm_eps`: `Some(eps)` adds the per-head LayerNorms on queries and keys.
    pub fn new(dim: usize, num_heads: usize, qk_norm_eps: Option<f64>, device: &Device) -> Self {
        let head_dim = dim / num_heads;
        let norm = |eps: f64| LayerNormConfig::new(head_dim).with_epsilon(eps).init(device);
        Self {
            qkv: LinearConfig::new(dim, 3 * dim).init(device),
            q_norm: qk_norm_eps.map(norm),
            k_norm: qk_norm_eps.map(norm),
            proj: LinearConfig::new(dim, dim).init(device),
            num_heads,
        }
    }

    /// `x`: `[batch, tokens, dim]`; `rope`, when given, must cover the `tokens` positions.
    pub fn forward(&self, x: Tensor<3>, rope: Option<&RopeTable>) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let h = self.num_heads;
        // [b, n, 3, h, d] -> [3, b, h, n, d]
        let qkv = self.qkv.forward(x).reshape([b, n, 3, h, c / h]).permute([2, 0, 3, 1, 4]);
        let head = |i: usize| qkv.clone().narrow(0, i, 1).squeeze_dim::<4>(0);
        let (mut q, mut k, v) = (head(0), head(1), head(2));
        if let Some(norm) = &self.q_norm {
            q = norm.forward(q);
        }
        if let Some(norm) = &self.k_norm {
            k = norm.forward(k);
        }
        if let Some(rope) = rope {
            q = rope.apply(q);
            k = rope.apply(k);
        }
        let out = attention(q, k, v, None, None, AttentionModuleOptions::default());
        self.proj.forward(out.swap_dims(1, 2).reshape([b, n, c]))
    }
}
