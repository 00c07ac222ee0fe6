//! The residual block shared by the VAE and the UNet: `GroupNorm -> SiLU -> conv3x3 [+ time embedding]
//! -> GroupNorm -> SiLU -> conv3x3`, added to the input (through a 1x1 convolution when the width changes).
//! The VAE's blocks have no time embedding; the UNet's add a projection of it per channel.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear};
use burn::tensor::Tensor;
use burn::tensor::activation::silu;

use crate::error::RefineError;
use crate::layers::{Bias, ConvShape, conv, group_norm, linear};
use crate::weights::Weights;

/// Sizes of one residual block.
#[derive(Debug, Clone, Copy)]
pub struct ResnetShape {
    pub channels_in: usize,
    pub channels_out: usize,
    pub groups: usize,
    pub epsilon: f64,
    /// Width of the time embedding the block adds, `None` without one.
    pub time_channels: Option<usize>,
}

#[derive(Module, Debug)]
pub struct ResnetBlock {
    norm1: GroupNorm,
    conv1: Conv2d,
    time_emb_proj: Option<Linear>,
    norm2: GroupNorm,
    conv2: Conv2d,
    conv_shortcut: Option<Conv2d>,
}

impl ResnetBlock {
    pub fn load(weights: &mut Weights, prefix: &str, shape: ResnetShape) -> Result<Self, RefineError> {
        let ResnetShape { channels_in, channels_out, groups, epsilon, time_channels } = shape;
        let time_emb_proj = time_channels
            .map(|width| linear(weights, &format!("{prefix}.time_emb_proj"), width, channels_out, Bias::With))
            .transpose()?;
        let conv_shortcut = (channels_in != channels_out)
            .then(|| {
                conv(
                    weights,
                    &format!("{prefix}.conv_shortcut"),
                    ConvShape::pointwise(channels_in, channels_out),
                    Bias::With,
                )
            })
            .transpose()?;
        Ok(Self {
            norm1: group_norm(weights, &format!("{prefix}.norm1"), groups, channels_in, epsilon)?,
            conv1: conv(weights, &format!("{prefix}.conv1"), ConvShape::same3(channels_in, channels_out), Bias::With)?,
            time_emb_proj,
            norm2: group_norm(weights, &format!("{prefix}.norm2"), groups, channels_out, epsilon)?,
            conv2: conv(weights, &format!("{prefix}.conv2"), ConvShape::same3(channels_out, channels_out), Bias::With)?,
            conv_shortcut,
        })
    }

    /// `x`: `[batch, channels_in, h, w]`; `time`: `[batch, time_channels]` for a block that takes one.
    pub fn forward(&self, x: Tensor<4>, time: Option<&Tensor<2>>) -> Tensor<4> {
        let mut h = self.conv1.forward(silu(self.norm1.forward(x.clone())));
        if let (Some(proj), Some(time)) = (&self.time_emb_proj, time) {
            let [batch, channels] = [h.dims()[0], h.dims()[1]];
            h = h + proj.forward(silu(time.clone())).reshape([batch, channels, 1, 1]);
        }
        let h = self.conv2.forward(silu(self.norm2.forward(h)));
        let shortcut = match &self.conv_shortcut {
            Some(conv) => conv.forward(x),
            None => x,
        };
        shortcut + h
    }
}
