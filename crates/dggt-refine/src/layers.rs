//! The leaf layers every block is made of (convolution, linear, group and layer norm), built from checkpoint
//! tensors under PyTorch names: `<prefix>.weight` / `<prefix>.bias`, Linear weights `[out, in]` (transposed
//! here to burn's `[in, out]`), convolution weights `[out, in, kh, kw]`.

use burn::module::Param;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, LayerNorm, LayerNormConfig, Linear, PaddingConfig2d};
use burn::tensor::Tensor;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};

use crate::error::RefineError;
use crate::weights::{StoredLayout, Weights};

/// Whether a layer has an additive bias.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bias {
    With,
    Without,
}

/// Shape of a square convolution: `kernel x kernel`, `stride`, zero `padding` as `[top, left, bottom, right]`.
#[derive(Debug, Clone, Copy)]
pub struct ConvShape {
    pub channels_in: usize,
    pub channels_out: usize,
    pub kernel: usize,
    pub stride: usize,
    pub padding: [usize; 4],
}

impl ConvShape {
    /// 3x3, stride 1, padding 1: the size-preserving convolution.
    pub fn same3(channels_in: usize, channels_out: usize) -> Self {
        Self { channels_in, channels_out, kernel: 3, stride: 1, padding: [1; 4] }
    }

    /// 1x1 pointwise convolution.
    pub fn pointwise(channels_in: usize, channels_out: usize) -> Self {
        Self { channels_in, channels_out, kernel: 1, stride: 1, padding: [0; 4] }
    }

    /// 3x3, stride 2, with the given padding: the halving convolution of the downsamplers.
    pub fn halving(channels: usize, padding: [usize; 4]) -> Self {
        Self { channels_in: channels, channels_out: channels, kernel: 3, stride: 2, padding }
    }
}

pub fn conv(weights: &mut Weights, prefix: &str, shape: ConvShape, bias: Bias) -> Result<Conv2d, RefineError> {
    let ConvShape { channels_in, channels_out, kernel, stride, padding } = shape;
    let weight = weights.take(&format!("{prefix}.weight"), [channels_out, channels_in, kernel, kernel])?;
    let bias = match bias {
        Bias::With => Some(taken(weights, &format!("{prefix}.bias"), [channels_out])?),
        Bias::Without => None,
    };
    let weight = recorded(weights, &format!("{prefix}.weight"), weight, StoredLayout::AsFile);
    Ok(Conv2d {
        weight,
        bias,
        stride: [stride, stride],
        kernel_size: [kernel, kernel],
        dilation: [1, 1],
        groups: 1,
        padding: PaddingConfig2d::Explicit(padding[0], padding[1], padding[2], padding[3]),
    })
}

pub fn linear(
    weights: &mut Weights,
    prefix: &str,
    features_in: usize,
    features_out: usize,
    bias: Bias,
) -> Result<Linear, RefineError> {
    let weight = weights.take(&format!("{prefix}.weight"), [features_out, features_in])?.transpose();
    let bias = match bias {
        Bias::With => Some(taken(weights, &format!("{prefix}.bias"), [features_out])?),
        Bias::Without => None,
    };
    let weight = recorded(weights, &format!("{prefix}.weight"), weight, StoredLayout::Transposed);
    Ok(Linear { weight, bias })
}

pub fn group_norm(
    weights: &mut Weights,
    prefix: &str,
    groups: usize,
    channels: usize,
    epsilon: f64,
) -> Result<GroupNorm, RefineError> {
    Ok(GroupNorm {
        gamma: Some(taken(weights, &format!("{prefix}.weight"), [channels])?),
        beta: Some(taken(weights, &format!("{prefix}.bias"), [channels])?),
        num_groups: groups,
        num_channels: channels,
        epsilon,
        affine: true,
    })
}

pub fn layer_norm(weights: &mut Weights, prefix: &str, dim: usize, epsilon: f64) -> Result<LayerNorm, RefineError> {
    let mut norm = LayerNormConfig::new(dim).with_epsilon(epsilon).init(weights.device());
    norm.gamma = taken(weights, &format!("{prefix}.weight"), [dim])?;
    norm.beta = Some(taken(weights, &format!("{prefix}.bias"), [dim])?);
    Ok(norm)
}

/// The parameter of file tensor `name`, recorded in `weights` under that name.
fn taken<const D: usize>(
    weights: &mut Weights,
    name: &str,
    shape: [usize; D],
) -> Result<Param<Tensor<D>>, RefineError> {
    let tensor = weights.take(name, shape)?;
    Ok(recorded(weights, name, tensor, StoredLayout::AsFile))
}

/// `tensor` as a parameter, recorded in `weights` under `name`.
fn recorded<const D: usize>(
    weights: &mut Weights,
    name: &str,
    tensor: Tensor<D>,
    layout: StoredLayout,
) -> Param<Tensor<D>> {
    let param = Param::from_tensor(tensor);
    weights.record(name, param.id, layout);
    param
}

/// Nearest-neighbour resize of `[batch, channels, h, w]` to `size` (`[height, width]`): source index
/// `floor(dst * in / out)`, PyTorch's `nearest`; an exact x2 repeats every pixel twice.
pub fn resize_nearest(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    interpolate(x, InterpolateOptions::new(InterpolateMode::Nearest).with_output_size(size))
}

/// `x` split into `[batch * views, tokens, dim]` chunks of `views` rows each joined along the tokens:
/// `[batch, views * tokens, dim]`, view 0's tokens first. [`split_views`] undoes it.
pub fn join_views(x: Tensor<3>, views: usize) -> Tensor<3> {
    let [rows, tokens, dim] = x.dims();
    x.reshape([rows / views, views * tokens, dim])
}

/// The inverse of [`join_views`].
pub fn split_views(x: Tensor<3>, views: usize) -> Tensor<3> {
    let [batch, joined, dim] = x.dims();
    x.reshape([batch * views, joined / views, dim])
}
