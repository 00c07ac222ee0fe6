//! The diffusers `AutoencoderKL` as the refiner uses it: the encoder keeps the activation entering each of its
//! down blocks, and the decoder adds a 1x1 projection of them ("skip convolutions") at the input of its up
//! blocks, deepest first. Decoder LoRA is merged into its weights when loading ([`crate::lora`]), so the
//! decoder here is a plain one with skips.
//!
//! Tensors are NCHW. The encoder takes images in [-1, 1]; the posterior is in unscaled latent units (the
//! refiner multiplies by the scaling factor); the decoder returns images in [-1, 1] scale, unclamped. The VAE
//! computes in the type of its parameters ([`Vae::with_float_dtype`]) behind an f32 interface.
//! GroupNorms use eps 1e-6. Downsampling pads one zero row below and one zero column right, then runs a
//! 3x3 stride-2 convolution; upsampling is nearest x2 then a 3x3 convolution.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear};
use burn::tensor::activation::silu;
use burn::tensor::{FloatDType, Tensor};
use dggt_model::attention::attend;
use dggt_model::leaf::CastFloats;

use crate::config::VaeConfig;
use crate::error::RefineError;
use crate::layers::{Bias, ConvShape, conv, group_norm, linear, resize_nearest};
use crate::resnet::{ResnetBlock, ResnetShape};
use crate::trace::Trace;
use crate::weights::Weights;

const NORM_EPS: f64 = 1e-6;
/// Bounds of the posterior's log-variance.
const LOGVAR_RANGE: (f32, f32) = (-30.0, 20.0);

/// The encoder's Gaussian posterior over latents (unscaled), and the skip sources.
pub struct Posterior {
    pub mean: Tensor<4>,
    pub std: Tensor<4>,
    /// The activation entering each encoder down block, shallowest first.
    pub down_inputs: Vec<Tensor<4>>,
}

#[derive(Module, Debug)]
pub struct Vae {
    encoder: Encoder,
    quant_conv: Conv2d,
    post_quant_conv: Conv2d,
    decoder: Decoder,
}

impl Vae {
    pub fn load(weights: &mut Weights, config: &VaeConfig) -> Result<Self, RefineError> {
        let moments = 2 * config.latent_channels;
        let latent = config.latent_channels;
        Ok(Self {
            encoder: Encoder::load(weights, config)?,
            quant_conv: conv(weights, "quant_conv", ConvShape::pointwise(moments, moments), Bias::With)?,
            post_quant_conv: conv(weights, "post_quant_conv", ConvShape::pointwise(latent, latent), Bias::With)?,
            decoder: Decoder::load(weights, config)?,
        })
    }

    /// The VAE with every float parameter in `dtype` (f32, f16, bf16). Its interface stays f32: it casts what it
    /// is given to `dtype` and its posterior and decoded images back to f32.
    pub fn with_float_dtype(self, dtype: FloatDType) -> Self {
        self.map(&mut CastFloats(dtype))
    }

    /// The float type the VAE computes in.
    pub fn float_dtype(&self) -> FloatDType {
        self.quant_conv.weight.val().dtype().into()
    }

    /// `x`: images `[rows, in_channels, h, w]` in [-1, 1]. The posterior's mean and std are f32, its
    /// `down_inputs` in the VAE's type.
    pub fn encode(&self, x: Tensor<4>, trace: &mut Trace) -> Posterior {
        let (h, down_inputs) = self.encoder.forward(x.cast(self.float_dtype()), trace);
        let moments = self.quant_conv.forward(h).cast(FloatDType::F32);
        let [mean, logvar] = moments.chunk(2, 1).try_into().expect("quant_conv has an even channel count");
        let std = (logvar.clamp(LOGVAR_RANGE.0, LOGVAR_RANGE.1) * 0.5).exp();
        trace.record("posterior.mean", &mean);
        trace.record("posterior.std", &std);
        Posterior { mean, std, down_inputs }
    }

    /// `latent`: unscaled latents `[rows, latent_channels, h/8, w/8]`; `down_inputs`: the same rows'
    /// [`Posterior::down_inputs`]. Returns `[rows, out_channels, h, w]` in [-1, 1] scale, unclamped.
    pub fn decode(&self, latent: Tensor<4>, down_inputs: &[Tensor<4>], trace: &mut Trace) -> Tensor<4> {
        let h = self.post_quant_conv.forward(latent.cast(self.float_dtype()));
        self.decoder.forward(h, down_inputs, trace).cast(FloatDType::F32)
    }
}

/// Residual blocks at one resolution, then an optional resize.
#[derive(Module, Debug)]
struct VaeLevel {
    resnets: Vec<ResnetBlock>,
    resample: Option<Conv2d>,
}

impl VaeLevel {
    fn load(
        weights: &mut Weights,
        prefix: &str,
        widths: (usize, usize),
        layers: usize,
        groups: usize,
        resample: Option<(&str, ConvShape)>,
    ) -> Result<Self, RefineError> {
        let resnets = (0..layers)
            .map(|j| {
                let channels_in = if j == 0 { widths.0 } else { widths.1 };
                let shape =
                    ResnetShape { channels_in, channels_out: widths.1, groups, epsilon: NORM_EPS, time_channels: None };
                ResnetBlock::load(weights, &format!("{prefix}.resnets.{j}"), shape)
            })
            .collect::<Result<_, _>>()?;
        let resample = resample
            .map(|(name, shape)| conv(weights, &format!("{prefix}.{name}.0.conv"), shape, Bias::With))
            .transpose()?;
        Ok(Self { resnets, resample })
    }

    fn resnets(&self, x: Tensor<4>) -> Tensor<4> {
        self.resnets.iter().fold(x, |h, resnet| resnet.forward(h, None))
    }
}

/// Single-head self-attention over the pixels, with a GroupNorm before and the residual after.
#[derive(Module, Debug)]
struct PixelAttention {
    group_norm: GroupNorm,
    to_q: Linear,
    to_k: Linear,
    to_v: Linear,
    to_out: Linear,
}

impl PixelAttention {
    fn load(weights: &mut Weights, prefix: &str, channels: usize, groups: usize) -> Result<Self, RefineError> {
        let mut proj = |name: &str| linear(weights, &format!("{prefix}.{name}"), channels, channels, Bias::With);
        Ok(Self {
            to_q: proj("to_q")?,
            to_k: proj("to_k")?,
            to_v: proj("to_v")?,
            to_out: proj("to_out.0")?,
            group_norm: group_norm(weights, &format!("{prefix}.group_norm"), groups, channels, NORM_EPS)?,
        })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [batch, channels, height, width] = x.dims();
        let tokens = self.group_norm.forward(x.clone()).reshape([batch, channels, height * width]).swap_dims(1, 2);
        let heads = |linear: &Linear| linear.forward(tokens.clone()).unsqueeze_dim::<4>(1);
        let attended = attend(heads(&self.to_q), heads(&self.to_k), heads(&self.to_v)).squeeze_dim::<3>(1);
        let out = self.to_out.forward(attended).swap_dims(1, 2).reshape([batch, channels, height, width]);
        x + out
    }
}

/// Residual block, pixel attention, residual block: the bottleneck of both encoder and decoder.
#[derive(Module, Debug)]
struct VaeMidBlock {
    first: ResnetBlock,
    attention: PixelAttention,
    second: ResnetBlock,
}

impl VaeMidBlock {
    fn load(weights: &mut Weights, prefix: &str, channels: usize, groups: usize) -> Result<Self, RefineError> {
        let shape = ResnetShape {
            channels_in: channels,
            channels_out: channels,
            groups,
            epsilon: NORM_EPS,
            time_channels: None,
        };
        Ok(Self {
            first: ResnetBlock::load(weights, &format!("{prefix}.resnets.0"), shape)?,
            attention: PixelAttention::load(weights, &format!("{prefix}.attentions.0"), channels, groups)?,
            second: ResnetBlock::load(weights, &format!("{prefix}.resnets.1"), shape)?,
        })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.second.forward(self.attention.forward(self.first.forward(x, None)), None)
    }
}

#[derive(Module, Debug)]
struct Encoder {
    conv_in: Conv2d,
    down: Vec<VaeLevel>,
    mid: VaeMidBlock,
    conv_norm_out: GroupNorm,
    conv_out: Conv2d,
}

impl Encoder {
    fn load(weights: &mut Weights, config: &VaeConfig) -> Result<Self, RefineError> {
        let widths = &config.block_out_channels;
        let groups = config.norm_num_groups;
        let deepest = *widths.last().expect("the configuration is checked to have levels");
        let down = (0..widths.len())
            .map(|i| {
                let channels_in = widths[i.saturating_sub(1)];
                // One zero row below and one zero column right, then no padding.
                let halving =
                    (i + 1 < widths.len()).then(|| ("downsamplers", ConvShape::halving(widths[i], [0, 0, 1, 1])));
                VaeLevel::load(
                    weights,
                    &format!("encoder.down_blocks.{i}"),
                    (channels_in, widths[i]),
                    config.layers_per_block,
                    groups,
                    halving,
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            conv_in: conv(weights, "encoder.conv_in", ConvShape::same3(config.in_channels, widths[0]), Bias::With)?,
            down,
            mid: VaeMidBlock::load(weights, "encoder.mid_block", deepest, groups)?,
            conv_norm_out: group_norm(weights, "encoder.conv_norm_out", groups, deepest, NORM_EPS)?,
            conv_out: conv(
                weights,
                "encoder.conv_out",
                ConvShape::same3(deepest, 2 * config.latent_channels),
                Bias::With,
            )?,
        })
    }

    /// The encoder's output (before `quant_conv`) and the activation entering each down block.
    fn forward(&self, x: Tensor<4>, trace: &mut Trace) -> (Tensor<4>, Vec<Tensor<4>>) {
        let mut h = self.conv_in.forward(x);
        let mut down_inputs = Vec::with_capacity(self.down.len());
        for (i, level) in self.down.iter().enumerate() {
            trace.record(format!("enc.down_in.{i}"), &h);
            down_inputs.push(h.clone());
            h = level.resnets(h);
            if let Some(halving) = &level.resample {
                h = halving.forward(h);
            }
        }
        let h = self.mid.forward(h);
        (self.conv_out.forward(silu(self.conv_norm_out.forward(h))), down_inputs)
    }
}

#[derive(Module, Debug)]
struct Decoder {
    conv_in: Conv2d,
    mid: VaeMidBlock,
    up: Vec<VaeLevel>,
    /// `skip_conv_{i+1}`: projects encoder down input `N-1-i` to the width entering up block `i`.
    skip_convs: Vec<Conv2d>,
    conv_norm_out: GroupNorm,
    conv_out: Conv2d,
}

impl Decoder {
    fn load(weights: &mut Weights, config: &VaeConfig) -> Result<Self, RefineError> {
        let widths: Vec<usize> = config.block_out_channels.iter().rev().copied().collect();
        let levels = widths.len();
        let groups = config.norm_num_groups;
        let up = (0..levels)
            .map(|i| {
                let channels_in = widths[i.saturating_sub(1)];
                let doubling = (i + 1 < levels).then(|| ("upsamplers", ConvShape::same3(widths[i], widths[i])));
                VaeLevel::load(
                    weights,
                    &format!("decoder.up_blocks.{i}"),
                    (channels_in, widths[i]),
                    config.layers_per_block + 1,
                    groups,
                    doubling,
                )
            })
            .collect::<Result<_, _>>()?;
        let skip_convs = (0..levels)
            .map(|i| {
                // Encoder down input k is the output of level k-1 (input 0 is conv_in's, of level 0's width).
                let source = config.block_out_channels[(levels - 1 - i).saturating_sub(1)];
                let target = widths[i.saturating_sub(1)];
                let shape = ConvShape::pointwise(source, target);
                conv(weights, &format!("decoder.skip_conv_{}", i + 1), shape, Bias::Without)
            })
            .collect::<Result<_, _>>()?;
        let shallowest = widths[levels - 1];
        Ok(Self {
            conv_in: conv(weights, "decoder.conv_in", ConvShape::same3(config.latent_channels, widths[0]), Bias::With)?,
            mid: VaeMidBlock::load(weights, "decoder.mid_block", widths[0], groups)?,
            up,
            skip_convs,
            conv_norm_out: group_norm(weights, "decoder.conv_norm_out", groups, shallowest, NORM_EPS)?,
            conv_out: conv(weights, "decoder.conv_out", ConvShape::same3(shallowest, config.out_channels), Bias::With)?,
        })
    }

    fn forward(&self, latent: Tensor<4>, down_inputs: &[Tensor<4>], trace: &mut Trace) -> Tensor<4> {
        let mut h = self.mid.forward(self.conv_in.forward(latent));
        for (i, (level, skip_conv)) in self.up.iter().zip(&self.skip_convs).enumerate() {
            let skip = skip_conv.forward(down_inputs[down_inputs.len() - 1 - i].clone());
            trace.record(format!("dec.skip.{}", i + 1), &skip);
            h = level.resnets(h + skip);
            if let Some(doubling) = &level.resample {
                let [_, _, height, width] = h.dims();
                h = doubling.forward(resize_nearest(h, [2 * height, 2 * width]));
            }
        }
        let out = self.conv_out.forward(silu(self.conv_norm_out.forward(h)));
        trace.record("dec.out", &out);
        out
    }
}
