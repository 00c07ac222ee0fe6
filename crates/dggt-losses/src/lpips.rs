//! LPIPS (learned perceptual image patch similarity), version 0.1 of the lpips package, with the AlexNet or
//! VGG-16 backbone.
//!
//! For images `x0`, `x1` (`[V, H, W, 3]` channel-last at the API, converted to NCHW inside):
//! 1. network input in [-1, 1]: [`LpipsInput::ZeroOne`] maps [0, 1] images by `2x - 1` (the evaluation
//!    metric); [`LpipsInput::Unscaled`] passes the values as they are (the release's training call, which
//!    feeds [0, 1] images unscaled);
//! 2. `x' = (x - SHIFT) / SCALE` per channel;
//! 3. backbone taps `f` (relu1..relu5, [`crate::backbone`]);
//! 4. per tap and pixel, unit length over channels: `f / (sqrt(sum_c f^2) + 1e-10)`;
//! 5. `d = (f0 - f1)^2`, a 1x1 convolution without bias to one channel (the learned `lin` weights, which
//!    are non-negative in the released files), mean over the pixels;
//! 6. LPIPS = sum over the taps.
//!
//! Under the square root a further 1e-20 is added: it keeps the gradient finite where a tap is exactly zero
//! over all channels (where `sqrt` has an infinite derivative), and changes no value by more than f32
//! rounding wherever `sum_c f^2` exceeds 1e-13 (where it is smaller, `f / norm` is below 1e-3 either way).
//!
//! The linear weights are read from the lpips package's `alex.pth` / `vgg.pth` (`linK.model.1.weight`,
//! `(1, C, 1, 1)`), from a full LPIPS state dict (also as `lins.K.model.1.weight`), or from safetensors with
//! the same names.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};

use crate::backbone::{ALEXNET_TAP_CHANNELS, AlexNet, VGG16_TAP_CHANNELS, Vgg16};
use crate::error::LossError;
use crate::images::{check_rgb, check_rgb_pair, to_nchw};
use crate::weights::WeightFile;

/// Per-channel shift of the lpips scaling layer (RGB).
pub const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
/// Per-channel scale of the lpips scaling layer (RGB).
pub const SCALE: [f32; 3] = [0.458, 0.448, 0.450];
/// Added to the channel norm before dividing.
pub const NORM_EPS: f32 = 1e-10;
/// Added to `sum_c f^2` under the square root (see the module docs).
pub const NORM_SQRT_EPS: f32 = 1e-20;

/// The backbone of an LPIPS network.
#[derive(Debug, Clone)]
pub enum LpipsNet {
    Alex(AlexNet),
    Vgg(Vgg16),
}

impl LpipsNet {
    /// Channels of the taps.
    pub fn tap_channels(&self) -> [usize; 5] {
        match self {
            Self::Alex(_) => ALEXNET_TAP_CHANNELS,
            Self::Vgg(_) => VGG16_TAP_CHANNELS,
        }
    }

    /// The five taps of an NCHW batch.
    pub fn taps(&self, x: Tensor<4>) -> Result<Vec<Tensor<4>>, LossError> {
        match self {
            Self::Alex(net) => net.taps(x),
            Self::Vgg(net) => net.taps(x),
        }
    }
}

/// Which backbone to load (`alex` or `vgg` in configurations).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LpipsKind {
    Alex,
    Vgg,
}

/// How the images' values reach the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LpipsInput {
    /// Images in [0, 1], mapped to [-1, 1] by `2x - 1` (LPIPS as an evaluation metric).
    ZeroOne,
    /// Values passed unscaled (the release's training loss on [0, 1] images).
    Unscaled,
}

/// LPIPS values of a batch of image pairs.
#[derive(Debug, Clone)]
pub struct LpipsOutput {
    /// `[V]`: LPIPS per image pair.
    pub value: Tensor<1>,
    /// `[V, 5]`: the contribution of each tap (sums to `value`).
    pub per_layer: Tensor<2>,
}

/// An LPIPS network: frozen backbone and linear weights.
#[derive(Debug, Clone)]
pub struct Lpips {
    net: LpipsNet,
    /// Per tap, the `[C]` weights of the 1x1 convolution.
    linear: Vec<Tensor<1>>,
}

impl Lpips {
    /// Loads the backbone from `backbone_path` (torchvision or lpips names) and the linear weights from
    /// `linear_path` (the same file for a full LPIPS state dict).
    pub fn load(
        kind: LpipsKind,
        backbone_path: impl AsRef<Path>,
        linear_path: impl AsRef<Path>,
        device: &Device,
    ) -> Result<Self, LossError> {
        let backbone_file = WeightFile::open(backbone_path)?;
        let net = match kind {
            LpipsKind::Alex => LpipsNet::Alex(AlexNet::from_file(&backbone_file, device)?),
            LpipsKind::Vgg => LpipsNet::Vgg(Vgg16::from_file(&backbone_file, 5, device)?),
        };
        let linear_file =
            if linear_path.as_ref() == backbone_file.path() { backbone_file } else { WeightFile::open(linear_path)? };
        Self::from_file(net, &linear_file, device)
    }

    /// Builds LPIPS on `net` with the linear weights of an opened weight file.
    pub fn from_file(net: LpipsNet, linear: &WeightFile, device: &Device) -> Result<Self, LossError> {
        let linear = net
            .tap_channels()
            .iter()
            .enumerate()
            .map(|(k, &c)| {
                let names = [format!("lin{k}.model.1.weight"), format!("lins.{k}.model.1.weight")];
                Ok(linear.tensor::<4>(&names, [1, c, 1, 1], device)?.reshape([c]))
            })
            .collect::<Result<_, LossError>>()?;
        Ok(Self { net, linear })
    }

    /// Builds LPIPS on `net` from the five linear weight vectors (`[C_k]` each, non-negative in the release).
    pub fn new(net: LpipsNet, linear: Vec<Tensor<1>>) -> Result<Self, LossError> {
        let channels = net.tap_channels();
        let found: Vec<usize> = linear.iter().map(|w| w.dims()[0]).collect();
        if found != channels {
            return Err(LossError::InvalidInput(format!(
                "LPIPS linear weights have {found:?} channels, the backbone's taps {channels:?}"
            )));
        }
        Ok(Self { net, linear })
    }

    /// The backbone.
    pub fn net(&self) -> &LpipsNet {
        &self.net
    }

    /// The linear weights, `[C_k]` per tap.
    pub fn linear(&self) -> &[Tensor<1>] {
        &self.linear
    }

    /// Channel-normalised taps `f / (||f||_c + 1e-10)` of `[V, H, W, 3]` images, NCHW.
    pub fn normalized_features(&self, images: Tensor<4>, input: LpipsInput) -> Result<Vec<Tensor<4>>, LossError> {
        check_rgb("LPIPS input", &images)?;
        let x = scale_input(to_nchw(images), input);
        Ok(self.net.taps(x)?.into_iter().map(normalize_channels).collect())
    }

    /// LPIPS between two `[V, H, W, 3]` batches: `[V]` values and `[V, 5]` per-tap contributions.
    pub fn forward(&self, img0: Tensor<4>, img1: Tensor<4>, input: LpipsInput) -> Result<LpipsOutput, LossError> {
        let [v, ..] = check_rgb_pair(&img0, &img1)?;
        // One pass through the backbone for both batches.
        let features = self.normalized_features(Tensor::cat(vec![img0, img1], 0), input)?;
        let per_layer: Vec<Tensor<2>> = features
            .into_iter()
            .zip(&self.linear)
            .map(|(f, weights)| {
                let [_, c, h, w] = f.dims();
                let diff = (f.clone().narrow(0, 0, v) - f.narrow(0, v, v)).square();
                let weighted = (diff * weights.clone().reshape([1, c, 1, 1])).sum_dim(1);
                weighted.reshape([v, h * w]).mean_dim(1)
            })
            .collect();
        let per_layer = Tensor::cat(per_layer, 1);
        Ok(LpipsOutput { value: per_layer.clone().sum_dim(1).reshape([v]), per_layer })
    }

    /// LPIPS as the evaluation metric: [0, 1] images mapped to [-1, 1]. `[V]`.
    pub fn eval(&self, rendered: Tensor<4>, target: Tensor<4>) -> Result<Tensor<1>, LossError> {
        Ok(self.forward(rendered, target, LpipsInput::ZeroOne)?.value)
    }

    /// LPIPS as the release trains with it: [0, 1] images passed unscaled. `[V]`.
    pub fn train_style(&self, rendered: Tensor<4>, target: Tensor<4>) -> Result<Tensor<1>, LossError> {
        Ok(self.forward(rendered, target, LpipsInput::Unscaled)?.value)
    }
}

/// `[N, 3, H, W]` network input: optional `2x - 1`, then `(x - SHIFT) / SCALE`.
pub fn scale_input(x: Tensor<4>, input: LpipsInput) -> Tensor<4> {
    let x = match input {
        LpipsInput::ZeroOne => x.mul_scalar(2.0).sub_scalar(1.0),
        LpipsInput::Unscaled => x,
    };
    let device = x.device();
    let shift = Tensor::<4>::from_data(TensorData::new(SHIFT.to_vec(), [1, 3, 1, 1]), &device);
    let scale = Tensor::<4>::from_data(TensorData::new(SCALE.to_vec(), [1, 3, 1, 1]), &device);
    (x - shift) / scale
}

/// `f / (sqrt(sum_c f^2 + 1e-20) + 1e-10)` over the channels of an NCHW tensor.
pub fn normalize_channels(f: Tensor<4>) -> Tensor<4> {
    let norm = f.clone().square().sum_dim(1).add_scalar(NORM_SQRT_EPS).sqrt().add_scalar(NORM_EPS);
    f / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host(t: Tensor<4>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    #[test]
    fn channels_are_normalised_to_unit_length() {
        let device = Device::flex();
        // Two pixels, two channels: (3, 4) and (0, 0).
        let f = Tensor::<4>::from_data(TensorData::new(vec![3.0f32, 0.0, 4.0, 0.0], [1, 2, 1, 2]), &device);
        let n = host(normalize_channels(f));
        assert!((n[0] - 0.6).abs() < 1e-6 && (n[2] - 0.8).abs() < 1e-6, "{n:?}");
        assert_eq!((n[1], n[3]), (0.0, 0.0));
    }

    #[test]
    fn input_scaling() {
        let device = Device::flex();
        let x = Tensor::<4>::from_data(TensorData::new(vec![1.0f32, 0.5, 0.0], [1, 3, 1, 1]), &device);
        let eval = host(scale_input(x.clone(), LpipsInput::ZeroOne));
        let train = host(scale_input(x, LpipsInput::Unscaled));
        let inputs = [1.0f32, 0.5, 0.0];
        for c in 0..3 {
            let expected_eval = (2.0 * inputs[c] - 1.0 - SHIFT[c]) / SCALE[c];
            let expected_train = (inputs[c] - SHIFT[c]) / SCALE[c];
            assert!((eval[c] - expected_eval).abs() < 1e-6 && (train[c] - expected_train).abs() < 1e-6);
        }
    }
}
