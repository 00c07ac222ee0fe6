//! The CLIP text encoder (transformers' `CLIPTextModel`): token plus learned position embeddings, pre-LN
//! transformer layers with causal self-attention, and a final LayerNorm; its last hidden state is the
//! UNet's cross-attention context. The refiner's prompt is fixed, so it runs once at load time.
//!
//! Keys are read with or without transformers' `text_model.` prefix.

use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::{LayerNorm, Linear};
use burn::tensor::activation::{gelu, sigmoid};
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Int, Tensor, TensorData};

use crate::config::TextEncoderConfig;
use crate::error::RefineError;
use crate::layers::{Bias, layer_norm, linear};
use crate::weights::Weights;

/// The feed-forward's activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Activation {
    /// Exact (erf) GELU, as SD 2.x's OpenCLIP encoder.
    Gelu,
    /// `x * sigmoid(1.702 x)`, as SD 1.x's CLIP.
    QuickGelu,
}

impl Activation {
    fn parse(name: &str, path: &Path) -> Result<Self, RefineError> {
        match name {
            "gelu" => Ok(Self::Gelu),
            "quick_gelu" => Ok(Self::QuickGelu),
            other => Err(RefineError::Config {
                path: path.display().to_string(),
                message: format!("hidden_act {other} (expected gelu or quick_gelu)"),
            }),
        }
    }

    fn apply(self, x: Tensor<3>) -> Tensor<3> {
        match self {
            Self::Gelu => gelu(x),
            Self::QuickGelu => x.clone() * sigmoid(x * 1.702),
        }
    }
}

#[derive(Module, Debug)]
pub struct TextEncoder {
    token_embedding: Param<Tensor<2>>,
    position_embedding: Param<Tensor<2>>,
    layers: Vec<EncoderLayer>,
    final_layer_norm: LayerNorm,
}

impl TextEncoder {
    /// `path`: the configuration's file, for error messages.
    pub fn load(weights: &mut Weights, config: &TextEncoderConfig, path: &Path) -> Result<Self, RefineError> {
        let activation = Activation::parse(&config.hidden_act, path)?;
        let root = if weights.contains("text_model.final_layer_norm.weight") { "text_model." } else { "" };
        let d = config.hidden_size;
        let eps = config.layer_norm_eps;
        let layers = (0..config.num_hidden_layers)
            .map(|i| EncoderLayer::load(weights, &format!("{root}encoder.layers.{i}"), config, activation))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            token_embedding: Param::from_tensor(
                weights.take(&format!("{root}embeddings.token_embedding.weight"), [config.vocab_size, d])?,
            ),
            position_embedding: Param::from_tensor(
                weights.take(
                    &format!("{root}embeddings.position_embedding.weight"),
                    [config.max_position_embeddings, d],
                )?,
            ),
            layers,
            final_layer_norm: layer_norm(weights, &format!("{root}final_layer_norm"), d, eps)?,
        })
    }

    /// The last hidden state `[1, tokens, hidden]` for one prompt's token ids.
    pub fn forward(&self, token_ids: &[i64]) -> Result<Tensor<3>, RefineError> {
        let [vocab, _] = self.token_embedding.dims();
        let [positions, _] = self.position_embedding.dims();
        if token_ids.len() > positions || token_ids.is_empty() {
            return Err(RefineError::Input(format!("{} prompt tokens, expected 1 to {positions}", token_ids.len())));
        }
        if let Some(bad) = token_ids.iter().find(|&&id| id < 0 || id as usize >= vocab) {
            return Err(RefineError::Input(format!("prompt token id {bad} outside the vocabulary of {vocab}")));
        }
        let device = self.token_embedding.device();
        let ids = Tensor::<1, Int>::from_data(TensorData::new(token_ids.to_vec(), [token_ids.len()]), &device);
        let tokens =
            self.token_embedding.val().select(0, ids) + self.position_embedding.val().narrow(0, 0, token_ids.len());
        let h = self.layers.iter().fold(tokens.unsqueeze_dim::<3>(0), |h, layer| layer.forward(h));
        Ok(self.final_layer_norm.forward(h))
    }
}

#[derive(Module, Debug)]
struct EncoderLayer {
    layer_norm1: LayerNorm,
    q_proj: Linear,
    k_proj: Linear,
    v_proj: Linear,
    out_proj: Linear,
    layer_norm2: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
    #[module(skip)]
    activation: Activation,
}

impl EncoderLayer {
    fn load(
        weights: &mut Weights,
        prefix: &str,
        config: &TextEncoderConfig,
        activation: Activation,
    ) -> Result<Self, RefineError> {
        let d = config.hidden_size;
        let eps = config.layer_norm_eps;
        let mut proj = |name: &str| linear(weights, &format!("{prefix}.self_attn.{name}"), d, d, Bias::With);
        let (q_proj, k_proj, v_proj, out_proj) = (proj("q_proj")?, proj("k_proj")?, proj("v_proj")?, proj("out_proj")?);
        Ok(Self {
            layer_norm1: layer_norm(weights, &format!("{prefix}.layer_norm1"), d, eps)?,
            q_proj,
            k_proj,
            v_proj,
            out_proj,
            layer_norm2: layer_norm(weights, &format!("{prefix}.layer_norm2"), d, eps)?,
            fc1: linear(weights, &format!("{prefix}.mlp.fc1"), d, config.intermediate_size, Bias::With)?,
            fc2: linear(weights, &format!("{prefix}.mlp.fc2"), config.intermediate_size, d, Bias::With)?,
            heads: config.num_attention_heads,
            activation,
        })
    }

    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let [batch, tokens, dim] = x.dims();
        let normed = self.layer_norm1.forward(x.clone());
        let split = |linear: &Linear| {
            linear.forward(normed.clone()).reshape([batch, tokens, self.heads, dim / self.heads]).swap_dims(1, 2)
        };
        let causal = AttentionModuleOptions { is_causal: true, ..Default::default() };
        let attended = attention(split(&self.q_proj), split(&self.k_proj), split(&self.v_proj), None, None, causal);
        let x = x + self.out_proj.forward(attended.swap_dims(1, 2).reshape([batch, tokens, dim]));
        let hidden = self.activation.apply(self.fc1.forward(self.layer_norm2.forward(x.clone())));
        x + self.fc2.forward(hidden)
    }
}
