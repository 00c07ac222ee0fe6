//! The frozen feature networks of the perceptual losses: AlexNet (LPIPS) and VGG-16 (LPIPS-VGG and the Gram
//! loss), as their convolutional `features` stacks, returning the activations after chosen ReLUs ("taps").
//!
//! * AlexNet, in the layout the lpips package uses: conv1 11x11 stride 4 pad 2 + ReLU (tap) | maxpool 3 s2,
//!   conv2 5x5 pad 2 + ReLU (tap) | maxpool 3 s2, conv3 3x3 pad 1 + ReLU (tap), conv4 3x3 pad 1 + ReLU (tap),
//!   conv5 3x3 pad 1 + ReLU (tap). Tap channels 64, 192, 384, 256, 256.
//! * VGG-16: 13 convs 3x3 pad 1 + ReLU in five stages separated by 2x2 stride-2 max-pools; taps after the last
//!   ReLU of each stage: relu1_2, relu2_2, relu3_3, relu4_3, relu5_3 (torchvision `features` indices 3, 8,
//!   15, 22, 29). Tap channels 64, 128, 256, 512, 512. A network can be built with its first `stages` stages
//!   only (the Gram loss needs four, LPIPS five).
//!
//! Inputs and taps are NCHW tensors; the networks do no input normalisation (the losses do their own).
//!
//! Weights are read from torchvision-named files (`features.N.weight` / `features.N.bias`) or, as the same
//! tensors, under the lpips package's names (`net.sliceS.N.weight`), from `.pth` or `.safetensors`
//! ([`crate::weights`]). They are plain tensors, never parameters, so they get no gradient; gradients flow
//! to the input.

use std::path::Path;

use burn::tensor::activation::relu;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor};

use crate::error::LossError;
use crate::weights::WeightFile;

/// One convolution of a `features` stack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvSpec {
    /// Index in torchvision's `features` Sequential.
    pub index: usize,
    /// Stage (1-based): the lpips package's `net.slice{stage}`.
    pub stage: usize,
    pub in_channels: usize,
    pub out_channels: usize,
    pub kernel: usize,
    pub stride: usize,
    pub padding: usize,
}

impl ConvSpec {
    const fn new(
        index: usize,
        stage: usize,
        channels: [usize; 2],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> Self {
        Self { index, stage, in_channels: channels[0], out_channels: channels[1], kernel, stride, padding }
    }

    /// Accepted names of this conv's `weight` or `bias`: torchvision's first, then the lpips package's.
    pub fn names(&self, field: &str) -> Vec<String> {
        vec![format!("features.{}.{field}", self.index), format!("net.slice{}.{}.{field}", self.stage, self.index)]
    }
}

/// AlexNet's five convolutions.
pub const ALEXNET_CONVS: [ConvSpec; 5] = [
    ConvSpec::new(0, 1, [3, 64], 11, 4, 2),
    ConvSpec::new(3, 2, [64, 192], 5, 1, 2),
    ConvSpec::new(6, 3, [192, 384], 3, 1, 1),
    ConvSpec::new(8, 4, [384, 256], 3, 1, 1),
    ConvSpec::new(10, 5, [256, 256], 3, 1, 1),
];

/// Channels of AlexNet's taps relu1..relu5.
pub const ALEXNET_TAP_CHANNELS: [usize; 5] = [64, 192, 384, 256, 256];

/// VGG-16's thirteen convolutions.
pub const VGG16_CONVS: [ConvSpec; 13] = [
    ConvSpec::new(0, 1, [3, 64], 3, 1, 1),
    ConvSpec::new(2, 1, [64, 64], 3, 1, 1),
    ConvSpec::new(5, 2, [64, 128], 3, 1, 1),
    ConvSpec::new(7, 2, [128, 128], 3, 1, 1),
    ConvSpec::new(10, 3, [128, 256], 3, 1, 1),
    ConvSpec::new(12, 3, [256, 256], 3, 1, 1),
    ConvSpec::new(14, 3, [256, 256], 3, 1, 1),
    ConvSpec::new(17, 4, [256, 512], 3, 1, 1),
    ConvSpec::new(19, 4, [512, 512], 3, 1, 1),
    ConvSpec::new(21, 4, [512, 512], 3, 1, 1),
    ConvSpec::new(24, 5, [512, 512], 3, 1, 1),
    ConvSpec::new(26, 5, [512, 512], 3, 1, 1),
    ConvSpec::new(28, 5, [512, 512], 3, 1, 1),
];

/// Channels of VGG-16's taps relu1_2, relu2_2, relu3_3, relu4_3, relu5_3.
pub const VGG16_TAP_CHANNELS: [usize; 5] = [64, 128, 256, 512, 512];

/// Names of VGG-16's taps.
pub const VGG16_TAP_NAMES: [&str; 5] = ["relu1_2", "relu2_2", "relu3_3", "relu4_3", "relu5_3"];

/// A loaded convolution (weights frozen).
#[derive(Debug, Clone)]
pub struct Conv {
    pub spec: ConvSpec,
    /// `[out, in, k, k]`.
    pub weight: Tensor<4>,
    /// `[out]`.
    pub bias: Tensor<1>,
}

impl Conv {
    fn load(spec: ConvSpec, file: &WeightFile, device: &Device) -> Result<Self, LossError> {
        let weight = file.tensor(
            &spec.names("weight"),
            [spec.out_channels, spec.in_channels, spec.kernel, spec.kernel],
            device,
        )?;
        let bias = file.tensor(&spec.names("bias"), [spec.out_channels], device)?;
        Ok(Self { spec, weight, bias })
    }

    /// Convolution followed by ReLU.
    pub fn forward_relu(&self, x: Tensor<4>) -> Tensor<4> {
        let (s, p) = (self.spec.stride, self.spec.padding);
        relu(conv2d(x, self.weight.clone(), Some(self.bias.clone()), ConvOptions::new([s, s], [p, p], [1, 1], 1)))
    }
}

fn max_pool(x: Tensor<4>, kernel: usize, stride: usize) -> Tensor<4> {
    max_pool2d(x, MaxPoolOptions::new([kernel, kernel]).with_stride([stride, stride]))
}

fn check_input(name: &str, x: &Tensor<4>, min_size: usize) -> Result<(), LossError> {
    let [n, c, h, w] = x.dims();
    if n == 0 || c != 3 || h < min_size || w < min_size {
        return Err(LossError::InvalidInput(format!(
            "{name} takes [N, 3, H, W] with N > 0 and H, W >= {min_size}, got {:?}",
            x.dims()
        )));
    }
    Ok(())
}

/// AlexNet `features` (lpips layout), weights frozen.
#[derive(Debug, Clone)]
pub struct AlexNet {
    pub convs: Vec<Conv>,
}

impl AlexNet {
    /// Smallest input height and width for which every tap is non-empty.
    pub const MIN_SIZE: usize = 31;

    /// Loads the five convs from a torchvision- or lpips-named `.pth` / `.safetensors` file.
    pub fn load(path: impl AsRef<Path>, device: &Device) -> Result<Self, LossError> {
        Self::from_file(&WeightFile::open(path)?, device)
    }

    /// Takes the five convs from an opened weight file.
    pub fn from_file(file: &WeightFile, device: &Device) -> Result<Self, LossError> {
        let convs = ALEXNET_CONVS.iter().map(|&spec| Conv::load(spec, file, device)).collect::<Result<_, _>>()?;
        Ok(Self { convs })
    }

    /// The activations after relu1..relu5 of an NCHW batch `[N, 3, H, W]` (H, W >= [`Self::MIN_SIZE`]).
    pub fn taps(&self, x: Tensor<4>) -> Result<Vec<Tensor<4>>, LossError> {
        check_input("AlexNet", &x, Self::MIN_SIZE)?;
        let mut taps = Vec::with_capacity(5);
        let mut x = x;
        for (i, conv) in self.convs.iter().enumerate() {
            if i == 1 || i == 2 {
                x = max_pool(x, 3, 2);
            }
            x = conv.forward_relu(x);
            taps.push(x.clone());
        }
        Ok(taps)
    }
}

/// VGG-16 `features` up to the end of stage `stages` (1..=5), weights frozen.
#[derive(Debug, Clone)]
pub struct Vgg16 {
    pub convs: Vec<Conv>,
    stages: usize,
}

impl Vgg16 {
    /// Loads the convs of the first `stages` stages (1..=5) from a torchvision- or lpips-named file.
    pub fn load(path: impl AsRef<Path>, stages: usize, device: &Device) -> Result<Self, LossError> {
        Self::from_file(&WeightFile::open(path)?, stages, device)
    }

    /// Takes the convs of the first `stages` stages (1..=5) from an opened weight file.
    pub fn from_file(file: &WeightFile, stages: usize, device: &Device) -> Result<Self, LossError> {
        if !(1..=5).contains(&stages) {
            return Err(LossError::InvalidInput(format!("VGG-16 has stages 1..=5, asked for {stages}")));
        }
        let convs = VGG16_CONVS
            .iter()
            .filter(|spec| spec.stage <= stages)
            .map(|&spec| Conv::load(spec, file, device))
            .collect::<Result<_, _>>()?;
        Ok(Self { convs, stages })
    }

    /// Number of stages (and taps).
    pub fn stages(&self) -> usize {
        self.stages
    }

    /// Smallest input height and width for which every tap is non-empty: `2^(stages - 1)`.
    pub fn min_size(&self) -> usize {
        1 << (self.stages - 1)
    }

    /// The activations after relu1_2, relu2_2, ... (one per stage) of an NCHW batch `[N, 3, H, W]`.
    pub fn taps(&self, x: Tensor<4>) -> Result<Vec<Tensor<4>>, LossError> {
        check_input("VGG-16", &x, self.min_size())?;
        let mut taps = Vec::with_capacity(self.stages);
        let mut x = x;
        let mut stage = 1;
        for (i, conv) in self.convs.iter().enumerate() {
            if conv.spec.stage != stage {
                taps.push(x.clone());
                x = max_pool(x, 2, 2);
                stage = conv.spec.stage;
            }
            x = conv.forward_relu(x);
            if i + 1 == self.convs.len() {
                taps.push(x.clone());
            }
        }
        Ok(taps)
    }
}
