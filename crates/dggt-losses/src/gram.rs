//! The Gram (style) loss on VGG-16 features, comparing feature correlations rather than positions.
//!
//! For images `x0`, `x1` (`[V, H, W, 3]`, [0, 1] linear RGB at the API, NCHW inside):
//! 1. ImageNet normalisation `(x - IMAGENET_MEAN) / IMAGENET_STD` per channel;
//! 2. VGG-16 taps relu1_2, relu2_2, relu3_3, relu4_3 ([`crate::backbone::Vgg16`] with four stages);
//! 3. per tap `F` of shape `[C, h, w]`, reshaped `[C, h w]`: `G = F F^T / (C h w)`;
//! 4. per tap, the mean over the `C x C` entries of `(G0 - G1)^2`;
//! 5. the loss is the sum over the four taps (no layer weights).

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};

use crate::backbone::Vgg16;
use crate::error::LossError;
use crate::images::{check_rgb, check_rgb_pair, to_nchw};

/// ImageNet channel means (RGB).
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations (RGB).
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Number of VGG-16 taps the loss uses.
pub const GRAM_LAYERS: usize = 4;

/// Gram loss values of a batch of image pairs.
#[derive(Debug, Clone)]
pub struct GramOutput {
    /// `[V]`: loss per image pair.
    pub value: Tensor<1>,
    /// `[V, 4]`: per tap (relu1_2, relu2_2, relu3_3, relu4_3); sums to `value`.
    pub per_layer: Tensor<2>,
}

/// The Gram loss with its frozen VGG-16 (four stages).
#[derive(Debug, Clone)]
pub struct GramLoss {
    vgg: Vgg16,
}

impl GramLoss {
    /// Loads VGG-16 stages 1-4 (`features.0` to `features.21`) from a torchvision-named file.
    pub fn load(path: impl AsRef<Path>, device: &Device) -> Result<Self, LossError> {
        Self::new(Vgg16::load(path, GRAM_LAYERS, device)?)
    }

    /// Uses a loaded VGG-16 with at least four stages (only the first four taps are used).
    pub fn new(vgg: Vgg16) -> Result<Self, LossError> {
        if vgg.stages() < GRAM_LAYERS {
            return Err(LossError::InvalidInput(format!(
                "the Gram loss needs VGG-16 stages 1-{GRAM_LAYERS}, the network has {}",
                vgg.stages()
            )));
        }
        Ok(Self { vgg })
    }

    /// Gram matrices `[V, C, C]` of the four taps of `[V, H, W, 3]` images (H, W >= 8).
    pub fn gram_matrices(&self, images: Tensor<4>) -> Result<Vec<Tensor<3>>, LossError> {
        check_rgb("Gram loss input", &images)?;
        let x = imagenet_normalize(to_nchw(images));
        Ok(self.vgg.taps(x)?.into_iter().take(GRAM_LAYERS).map(gram_matrix).collect())
    }

    /// The loss between two `[V, H, W, 3]` batches: `[V]` values and `[V, 4]` per tap.
    pub fn forward(&self, img0: Tensor<4>, img1: Tensor<4>) -> Result<GramOutput, LossError> {
        let [v, ..] = check_rgb_pair(&img0, &img1)?;
        let grams = self.gram_matrices(Tensor::cat(vec![img0, img1], 0))?;
        let per_layer: Vec<Tensor<2>> = grams
            .into_iter()
            .map(|g| {
                let [_, c, _] = g.dims();
                (g.clone().narrow(0, 0, v) - g.narrow(0, v, v)).square().reshape([v, c * c]).mean_dim(1)
            })
            .collect();
        let per_layer = Tensor::cat(per_layer, 1);
        Ok(GramOutput { value: per_layer.clone().sum_dim(1).reshape([v]), per_layer })
    }
}

/// `(x - IMAGENET_MEAN) / IMAGENET_STD` per channel of an NCHW `[N, 3, H, W]` tensor.
pub fn imagenet_normalize(x: Tensor<4>) -> Tensor<4> {
    let device = x.device();
    let mean = Tensor::<4>::from_data(TensorData::new(IMAGENET_MEAN.to_vec(), [1, 3, 1, 1]), &device);
    let std = Tensor::<4>::from_data(TensorData::new(IMAGENET_STD.to_vec(), [1, 3, 1, 1]), &device);
    (x - mean) / std
}

/// Gram matrices `F F^T / (C h w)` of NCHW features `[N, C, h, w]`, with `F` the `[C, h w]` reshape: `[N, C, C]`.
pub fn gram_matrix(features: Tensor<4>) -> Tensor<3> {
    let [n, c, h, w] = features.dims();
    let f = features.reshape([n, c, h * w]);
    f.clone().matmul(f.swap_dims(1, 2)).div_scalar((c * h * w) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gram_matrix_of_known_features() {
        // One image, C = 2, 1x2 pixels: F = [[1, 2], [3, 4]] -> F F^T / 4 = [[5, 11], [11, 25]] / 4.
        let device = Device::flex();
        let f = Tensor::<4>::from_data(TensorData::new(vec![1.0f32, 2.0, 3.0, 4.0], [1, 2, 1, 2]), &device);
        let g = gram_matrix(f).into_data().try_into_vec::<f32>().unwrap();
        assert_eq!(g, [1.25, 2.75, 2.75, 6.25]);
    }

    #[test]
    fn imagenet_normalisation_per_channel() {
        let device = Device::flex();
        let x = Tensor::<4>::from_data(TensorData::new(IMAGENET_MEAN.to_vec(), [1, 3, 1, 1]), &device);
        let y = imagenet_normalize(x.add_scalar(0.5)).into_data().try_into_vec::<f32>().unwrap();
        for (v, s) in y.iter().zip(IMAGENET_STD) {
            assert!((v - 0.5 / s).abs() < 1e-5, "{y:?}");
        }
    }
}
