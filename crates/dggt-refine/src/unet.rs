//! The denoiser: diffusers' `UNet2DConditionModel` in the SD 2.1 layout (plain and cross-attention levels,
//! linear projections in its transformers, per-level head counts), predicting the noise `eps` of latents
//! `[rows, in_channels, h, w]` at one timestep given prompt embeddings `[rows, tokens, context_dim]`.
//!
//! Up path: each level concatenates the down path's activations (last in, first out) before its residual
//! blocks. When a latent side is not a multiple of `2^upsamplers`, every upsampler resizes to the exact size
//! of the activation it is about to be joined with instead of doubling. Resnet GroupNorms use the config's
//! eps; downsamplers are 3x3 stride-2 convolutions padded by one on every side.
//!
//! The UNet computes in the type of its parameters ([`Unet::with_float_dtype`]); with `upcast_attention` its
//! attention runs in f32 whatever that type.

use std::path::Path;

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear};
use burn::tensor::activation::silu;
use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use dggt_model::leaf::CastFloats;

use crate::config::{UnetConfig, require};
use crate::error::RefineError;
use crate::layers::{Bias, ConvShape, conv, group_norm, linear, resize_nearest};
use crate::resnet::{ResnetBlock, ResnetShape};
use crate::trace::Trace;
use crate::transformer::{ScorePrecision, SpatialTransformer, TransformerShape, ViewAttention};
use crate::weights::Weights;

/// Period of the slowest sinusoid of the timestep features.
const MAX_PERIOD: f32 = 10_000.0;

/// Whether a level's residual blocks are each followed by a spatial transformer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LevelKind {
    Plain,
    CrossAttention,
}

impl LevelKind {
    fn parse(name: &str, path: &Path) -> Result<Self, RefineError> {
        match name {
            "DownBlock2D" | "UpBlock2D" => Ok(Self::Plain),
            "CrossAttnDownBlock2D" | "CrossAttnUpBlock2D" => Ok(Self::CrossAttention),
            other => {
                Err(RefineError::Config { path: path.display().to_string(), message: format!("block type {other}") })
            }
        }
    }
}

/// The inputs every level's blocks see besides the hidden state.
struct Conditioning<'a> {
    time: &'a Tensor<2>,
    context: &'a Tensor<3>,
    views: ViewAttention,
}

/// Residual blocks, each optionally followed by a transformer, then an optional resize convolution.
#[derive(Module, Debug)]
struct UnetLevel {
    resnets: Vec<ResnetBlock>,
    attentions: Vec<SpatialTransformer>,
    resample: Option<Conv2d>,
}

impl UnetLevel {
    fn forward_layer(&self, j: usize, h: Tensor<4>, conditioning: &Conditioning) -> Tensor<4> {
        let h = self.resnets[j].forward(h, Some(conditioning.time));
        match self.attentions.get(j) {
            Some(transformer) => transformer.forward(h, conditioning.context, conditioning.views),
            None => h,
        }
    }
}

#[derive(Module, Debug)]
struct TimeEmbedding {
    linear_1: Linear,
    linear_2: Linear,
    /// Width of the sinusoidal features.
    features: usize,
    flip_sin_to_cos: bool,
    freq_shift: f32,
}

impl TimeEmbedding {
    /// Sinusoidal features of `timestep` (`[cos | sin]` when flipped) for `rows` rows, then the MLP.
    fn forward(&self, timestep: usize, rows: usize, device: &Device) -> Tensor<2> {
        let half = self.features / 2;
        let angles: Vec<f32> = (0..half)
            .map(|k| timestep as f32 * (-MAX_PERIOD.ln() * k as f32 / (half as f32 - self.freq_shift)).exp())
            .collect();
        let sines = angles.iter().map(|a| a.sin());
        let cosines = angles.iter().map(|a| a.cos());
        let row: Vec<f32> =
            if self.flip_sin_to_cos { cosines.chain(sines).collect() } else { sines.chain(cosines).collect() };
        let features = Tensor::<1>::from_data(TensorData::new(row, [self.features]), device)
            .cast(self.linear_1.weight.val().dtype())
            .unsqueeze_dim::<2>(0)
            .repeat_dim(0, rows);
        self.linear_2.forward(silu(self.linear_1.forward(features)))
    }
}

#[derive(Module, Debug)]
pub struct Unet {
    time_embedding: TimeEmbedding,
    conv_in: Conv2d,
    down: Vec<UnetLevel>,
    mid: UnetLevel,
    up: Vec<UnetLevel>,
    conv_norm_out: GroupNorm,
    conv_out: Conv2d,
}

impl Unet {
    /// `path`: the configuration's file, for error messages.
    pub fn load(weights: &mut Weights, config: &UnetConfig, path: &Path) -> Result<Self, RefineError> {
        check(config, path)?;
        let builder = LevelBuilder::new(config);
        let widths = &config.block_out_channels;
        let levels = widths.len();
        let down = (0..levels)
            .map(|i| {
                let kind = LevelKind::parse(&config.down_block_types[i], path)?;
                builder.down(weights, i, kind)
            })
            .collect::<Result<_, _>>()?;
        let up = (0..levels)
            .map(|i| {
                let kind = LevelKind::parse(&config.up_block_types[i], path)?;
                builder.up(weights, i, kind)
            })
            .collect::<Result<_, _>>()?;
        let time_channels = builder.time_channels;
        Ok(Self {
            time_embedding: TimeEmbedding {
                linear_1: linear(weights, "time_embedding.linear_1", widths[0], time_channels, Bias::With)?,
                linear_2: linear(weights, "time_embedding.linear_2", time_channels, time_channels, Bias::With)?,
                features: widths[0],
                flip_sin_to_cos: config.flip_sin_to_cos,
                freq_shift: config.freq_shift as f32,
            },
            conv_in: conv(weights, "conv_in", ConvShape::same3(config.in_channels, widths[0]), Bias::With)?,
            down,
            mid: builder.mid(weights)?,
            up,
            conv_norm_out: group_norm(weights, "conv_norm_out", config.norm_num_groups, widths[0], config.norm_eps)?,
            conv_out: conv(weights, "conv_out", ConvShape::same3(widths[0], config.out_channels), Bias::With)?,
        })
    }

    /// The UNet with every float parameter in `dtype` (f32, f16, bf16); its inputs must then be in `dtype`.
    pub fn with_float_dtype(self, dtype: FloatDType) -> Self {
        self.map(&mut CastFloats(dtype))
    }

    /// The noise prediction for `latent` `[rows, c, h, w]` at `timestep`, given `context`
    /// `[rows, tokens, context_dim]`.
    pub fn forward(
        &self,
        latent: Tensor<4>,
        timestep: usize,
        context: &Tensor<3>,
        views: ViewAttention,
        trace: &mut Trace,
    ) -> Tensor<4> {
        let [rows, _, height, width] = latent.dims();
        let time = self.time_embedding.forward(timestep, rows, &latent.device());
        trace.record("unet.temb", &time);
        let conditioning = Conditioning { time: &time, context, views };
        let mut h = self.conv_in.forward(latent);
        trace.record("unet.conv_in", &h);
        let mut skips = vec![h.clone()];
        for (i, level) in self.down.iter().enumerate() {
            for j in 0..level.resnets.len() {
                h = level.forward_layer(j, h, &conditioning);
                skips.push(h.clone());
            }
            if let Some(halving) = &level.resample {
                h = halving.forward(h);
                skips.push(h.clone());
            }
            trace.record(format!("unet.down.{i}"), &h);
        }
        h = (0..self.mid.resnets.len()).fold(h, |h, j| self.mid.forward_layer(j, h, &conditioning));
        trace.record("unet.mid", &h);
        let upsamplers = self.up.iter().filter(|level| level.resample.is_some()).count();
        let exact_sizes = height % (1 << upsamplers) != 0 || width % (1 << upsamplers) != 0;
        for (i, level) in self.up.iter().enumerate() {
            for j in 0..level.resnets.len() {
                let skip = skips.pop().expect("the down path leaves one activation per up-path resnet");
                h = level.forward_layer(j, Tensor::cat(vec![h, skip], 1), &conditioning);
            }
            if let Some(doubling) = &level.resample {
                let [_, _, h_in, w_in] = h.dims();
                let size = match (exact_sizes, skips.last()) {
                    (true, Some(next)) => [next.dims()[2], next.dims()[3]],
                    _ => [2 * h_in, 2 * w_in],
                };
                h = doubling.forward(resize_nearest(h, size));
            }
            trace.record(format!("unet.up.{i}"), &h);
        }
        self.conv_out.forward(silu(self.conv_norm_out.forward(h)))
    }
}

/// Settings of the configuration this implementation does not cover are errors.
fn check(config: &UnetConfig, path: &Path) -> Result<(), RefineError> {
    let levels = config.block_out_channels.len();
    require(levels > 0, path, || "block_out_channels is empty".into())?;
    require(config.down_block_types.len() == levels && config.up_block_types.len() == levels, path, || {
        "down_block_types / up_block_types must have one entry per block_out_channels".into()
    })?;
    require(config.use_linear_projection, path, || "use_linear_projection false (convolution projections)".into())?;
    require(config.transformer_layers_per_block >= 1, path, || "transformer_layers_per_block 0".into())
}

/// Shapes of the UNet's levels, read from its configuration.
struct LevelBuilder<'a> {
    config: &'a UnetConfig,
    time_channels: usize,
}

impl<'a> LevelBuilder<'a> {
    fn new(config: &'a UnetConfig) -> Self {
        Self { config, time_channels: 4 * config.block_out_channels[0] }
    }

    fn heads(&self, level: usize) -> usize {
        self.config.num_attention_heads.as_ref().unwrap_or(&self.config.attention_head_dim).at(level)
    }

    fn resnet(&self, channels_in: usize, channels_out: usize) -> ResnetShape {
        ResnetShape {
            channels_in,
            channels_out,
            groups: self.config.norm_num_groups,
            epsilon: self.config.norm_eps,
            time_channels: Some(self.time_channels),
        }
    }

    fn transformer(&self, channels: usize, level: usize) -> TransformerShape {
        TransformerShape {
            channels,
            heads: self.heads(level),
            context_dim: self.config.cross_attention_dim,
            groups: self.config.norm_num_groups,
            layers: self.config.transformer_layers_per_block,
            scores: if self.config.upcast_attention { ScorePrecision::Float32 } else { ScorePrecision::Native },
        }
    }

    /// Residual blocks `channels_in[j] -> channels_out`, and their transformers for a cross-attention level.
    fn layers(
        &self,
        weights: &mut Weights,
        prefix: &str,
        channels_in: &[usize],
        channels_out: usize,
        kind: LevelKind,
        heads_level: usize,
    ) -> Result<(Vec<ResnetBlock>, Vec<SpatialTransformer>), RefineError> {
        let mut resnets = Vec::new();
        let mut attentions = Vec::new();
        for (j, &width_in) in channels_in.iter().enumerate() {
            resnets.push(ResnetBlock::load(
                weights,
                &format!("{prefix}.resnets.{j}"),
                self.resnet(width_in, channels_out),
            )?);
            if kind == LevelKind::CrossAttention {
                let shape = self.transformer(channels_out, heads_level);
                attentions.push(SpatialTransformer::load(weights, &format!("{prefix}.attentions.{j}"), shape)?);
            }
        }
        Ok((resnets, attentions))
    }

    fn down(&self, weights: &mut Weights, i: usize, kind: LevelKind) -> Result<UnetLevel, RefineError> {
        let widths = &self.config.block_out_channels;
        let prefix = format!("down_blocks.{i}");
        let mut channels_in = vec![widths[i]; self.config.layers_per_block];
        channels_in[0] = widths[i.saturating_sub(1)];
        let (resnets, attentions) = self.layers(weights, &prefix, &channels_in, widths[i], kind, i)?;
        let resample = (i + 1 < widths.len())
            .then(|| {
                conv(
                    weights,
                    &format!("{prefix}.downsamplers.0.conv"),
                    ConvShape::halving(widths[i], [1; 4]),
                    Bias::With,
                )
            })
            .transpose()?;
        Ok(UnetLevel { resnets, attentions, resample })
    }

    fn mid(&self, weights: &mut Weights) -> Result<UnetLevel, RefineError> {
        let levels = self.config.block_out_channels.len();
        let width = self.config.block_out_channels[levels - 1];
        let resnet = |weights: &mut Weights, j: usize| {
            ResnetBlock::load(weights, &format!("mid_block.resnets.{j}"), self.resnet(width, width))
        };
        let first = resnet(weights, 0)?;
        let shape = self.transformer(width, levels - 1);
        let attention = SpatialTransformer::load(weights, "mid_block.attentions.0", shape)?;
        let second = resnet(weights, 1)?;
        // Run as layers: resnet+transformer, then a resnet alone.
        Ok(UnetLevel { resnets: vec![first, second], attentions: vec![attention], resample: None })
    }

    /// Up level `i` (deepest first): its residual blocks take the previous level's output (or the one before)
    /// joined with the down path's activations, last in first out.
    fn up(&self, weights: &mut Weights, i: usize, kind: LevelKind) -> Result<UnetLevel, RefineError> {
        let reversed: Vec<usize> = self.config.block_out_channels.iter().rev().copied().collect();
        let levels = reversed.len();
        let width = reversed[i];
        let previous = reversed[i.saturating_sub(1)];
        let skip_last = reversed[(i + 1).min(levels - 1)];
        let layers = self.config.layers_per_block + 1;
        let channels_in: Vec<usize> = (0..layers)
            .map(|j| {
                let hidden = if j == 0 { previous } else { width };
                let skip = if j + 1 == layers { skip_last } else { width };
                hidden + skip
            })
            .collect();
        let prefix = format!("up_blocks.{i}");
        let (resnets, attentions) = self.layers(weights, &prefix, &channels_in, width, kind, levels - 1 - i)?;
        let resample = (i + 1 < levels)
            .then(|| conv(weights, &format!("{prefix}.upsamplers.0.conv"), ConvShape::same3(width, width), Bias::With))
            .transpose()?;
        Ok(UnetLevel { resnets, attentions, resample })
    }
}
