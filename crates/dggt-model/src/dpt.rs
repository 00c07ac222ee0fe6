//! The DPT head: dense per-pixel maps from four tapped layers of token features.
//!
//! Per tapped layer `i`: patch tokens -> LayerNorm -> 1x1 projection to `out_channels[i]` -> + UV positional
//! embedding ([`crate::uv_embed`]) -> resize to four scales (transposed conv x4, transposed conv x2, identity,
//! 3x3 conv stride 2) -> `layer{i}_rn` 3x3 conv to `features`. Fusion runs coarse to fine (`refinenet4..1`:
//! residual conv units, bilinear upsampling with align_corners, 1x1 conv), then `output_conv1` halves the
//! channels, the map is resized bilinearly to the image size, the positional embedding is added again, and
//! `output_conv2` (3x3 conv, ReLU, 1x1 conv) gives the raw output channels. With
//! [`DptConfig::pixel_skip`] (not in the release) a 3x3 convolution of the input image is added to the map
//! `output_conv2` reads.
//!
//! Release quirk kept here: the residual conv unit applies its first ReLU in place, so its skip connection
//! adds `relu(x)`, not `x`.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{LayerNorm, LayerNormConfig, PaddingConfig2d};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};

use crate::config::{DptConfig, DptHeadConfig, HeadActivation};
use crate::constant::ConstantSite;
use crate::conv;
use crate::leaf::replace_value;
use crate::resample::bilinear_aligned;
use crate::uv_embed::uv_sincos_embedding;

/// Scale of the UV positional embedding added to feature maps.
const POS_EMBED_RATIO: f32 = 0.1;
/// Frequency base of the UV positional embedding.
const POS_EMBED_OMEGA: f64 = 100.0;

fn conv3x3(input: usize, output: usize, bias: bool, device: &Device) -> Conv2d {
    Conv2dConfig::new([input, output], [3, 3])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .with_bias(bias)
        .init(device)
}

fn conv1x1(input: usize, output: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([input, output], [1, 1]).init(device)
}

/// Two 3x3 convs with a residual connection; see the module docs for the in-place-ReLU skip.
#[derive(Module, Debug)]
pub struct ResidualConvUnit {
    pub conv1: Conv2d,
    pub conv2: Conv2d,
}

impl ResidualConvUnit {
    fn new(features: usize, device: &Device) -> Self {
        Self { conv1: conv3x3(features, features, true, device), conv2: conv3x3(features, features, true, device) }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = relu(x);
        conv::conv2d(&self.conv2, relu(conv::conv2d(&self.conv1, x.clone()))) + x
    }
}

/// One fusion stage: optional skip input through `res_conf_unit1`, `res_conf_unit2`, bilinear upsampling,
/// 1x1 `out_conv`.
#[derive(Module, Debug)]
pub struct FusionBlock {
    pub res_conf_unit1: Option<ResidualConvUnit>,
    pub res_conf_unit2: ResidualConvUnit,
    pub out_conv: Conv2d,
}

impl FusionBlock {
    fn new(features: usize, has_skip: bool, device: &Device) -> Self {
        Self {
            res_conf_unit1: has_skip.then(|| ResidualConvUnit::new(features, device)),
            res_conf_unit2: ResidualConvUnit::new(features, device),
            out_conv: conv1x1(features, features, device),
        }
    }

    /// `size`: the output size, or twice the input size when `None`.
    pub fn forward(&self, x: Tensor<4>, skip: Option<Tensor<4>>, size: Option<[usize; 2]>) -> Tensor<4> {
        let x = match (&self.res_conf_unit1, skip) {
            (Some(unit), Some(skip)) => x + unit.forward(skip),
            (None, None) => x,
            _ => panic!("a fusion block takes a skip input exactly when it has res_conf_unit1"),
        };
        let x = self.res_conf_unit2.forward(x);
        let [_, _, h, w] = x.dims();
        conv::conv2d(&self.out_conv, bilinear_aligned(x, size.unwrap_or([2 * h, 2 * w])))
    }
}

/// The per-layer resampling to strides 4, 8, 14 (identity) and 28 pixels per cell.
#[derive(Module, Debug)]
pub struct ResizeLayers {
    /// `resize_layers.0`: transposed conv, kernel 4, stride 4.
    pub up4: ConvTranspose2d,
    /// `resize_layers.1`: transposed conv, kernel 2, stride 2.
    pub up2: ConvTranspose2d,
    /// `resize_layers.3`: 3x3 conv, stride 2, padding 1 (`resize_layers.2` is the identity).
    pub down2: Conv2d,
}

impl ResizeLayers {
    fn new(out_channels: [usize; 4], device: &Device) -> Self {
        let up = |c: usize, k: usize| ConvTranspose2dConfig::new([c, c], [k, k]).with_stride([k, k]).init(device);
        Self {
            up4: up(out_channels[0], 4),
            up2: up(out_channels[1], 2),
            down2: Conv2dConfig::new([out_channels[3], out_channels[3]], [3, 3])
                .with_stride([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device),
        }
    }

    pub fn forward(&self, level: usize, x: Tensor<4>) -> Tensor<4> {
        match level {
            0 => conv::conv_transpose2d(&self.up4, x),
            1 => conv::conv_transpose2d(&self.up2, x),
            2 => x,
            3 => self.down2.forward(x),
            _ => panic!("DPT has four levels, got level {level}"),
        }
    }
}

/// `output_conv2`: 3x3 conv, ReLU, 1x1 conv (`output_conv2.0` and `output_conv2.2` in the release).
#[derive(Module, Debug)]
pub struct OutputConv {
    pub hidden: Conv2d,
    pub out: Conv2d,
}

/// The fusion network (`scratch` in the release).
#[derive(Module, Debug)]
pub struct Scratch {
    pub layer1_rn: Conv2d,
    pub layer2_rn: Conv2d,
    pub layer3_rn: Conv2d,
    pub layer4_rn: Conv2d,
    pub refinenet1: FusionBlock,
    pub refinenet2: FusionBlock,
    pub refinenet3: FusionBlock,
    pub refinenet4: FusionBlock,
    pub output_conv1: Conv2d,
    pub output_conv2: OutputConv,
}

#[derive(Module, Debug)]
pub struct DptHead {
    pub norm: LayerNorm,
    pub projects: Vec<Conv2d>,
    pub resize_layers: ResizeLayers,
    pub scratch: Scratch,
    /// 3x3 convolution from the input image's RGB to `output_conv2`'s input channels ([`DptConfig::pixel_skip`]).
    pub pixel_skip: Option<Conv2d>,
    patch_size: usize,
    intermediate_layer_idx: [usize; 4],
    pos_embed: bool,
    /// Activations of the prediction channels and of the last (confidence) channel.
    #[module(skip)]
    activations: [HeadActivation; 2],
}

/// Intermediate and final maps of one DPT pass; maps are NCHW over the `B*S` frames.
#[derive(Debug, Clone)]
pub struct DptOutput {
    /// Each tapped layer after projection, positional embedding and resizing.
    pub resized: Vec<Tensor<4>>,
    /// `output_conv1` of the fused features, `[B*S, F/2, 8 rows, 8 cols]`.
    pub fused: Tensor<4>,
    /// Input of `output_conv2`: `fused` resized to the image and with the positional embedding,
    /// `[B*S, F/2, H, W]`.
    pub head_in: Tensor<4>,
    /// `output_conv2` output, channel-last `[B, S, H, W, output_dim]`.
    pub raw: Tensor<5>,
}

/// A DPT pass with its channels activated.
#[derive(Debug, Clone)]
pub struct DptPrediction {
    /// Internals and the raw output.
    pub dpt: DptOutput,
    /// Activated prediction channels, `[B, S, H, W, output_dim - 1]`.
    pub prediction: Tensor<5>,
    /// Activated confidence channel, `[B, S, H, W]`.
    pub confidence: Tensor<4>,
}

impl DptHead {
    pub fn new(common: &DptConfig, head: &DptHeadConfig, device: &Device) -> Self {
        let f = common.features;
        let oc = common.out_channels;
        let rn = |i: usize| conv3x3(oc[i], f, false, device);
        Self {
            norm: LayerNormConfig::new(head.dim_in).with_epsilon(common.layernorm_eps).init(device),
            projects: oc.iter().map(|&c| conv1x1(head.dim_in, c, device)).collect(),
            resize_layers: ResizeLayers::new(oc, device),
            scratch: Scratch {
                layer1_rn: rn(0),
                layer2_rn: rn(1),
                layer3_rn: rn(2),
                layer4_rn: rn(3),
                refinenet1: FusionBlock::new(f, true, device),
                refinenet2: FusionBlock::new(f, true, device),
                refinenet3: FusionBlock::new(f, true, device),
                refinenet4: FusionBlock::new(f, false, device),
                output_conv1: conv3x3(f, f / 2, true, device),
                output_conv2: OutputConv {
                    hidden: conv3x3(f / 2, common.head_features_2, true, device),
                    out: conv1x1(common.head_features_2, head.output_dim, device),
                },
            },
            pixel_skip: common.pixel_skip.then(|| conv3x3(3, f / 2, true, device)),
            patch_size: common.patch_size,
            intermediate_layer_idx: common.intermediate_layer_idx,
            pos_embed: common.pos_embed,
            activations: [head.activation, head.conf_activation],
        }
    }

    /// The head with its last 1x1 convolution zeroed: it predicts exactly zero until trained, while the
    /// gradients of that convolution are not zero.
    pub fn with_zero_output(self) -> Self {
        let channels = self.scratch.output_conv2.out.weight.dims()[0];
        self.with_zero_channels(0..channels)
    }

    /// The head with the rows of its last 1x1 convolution that produce output `channels` zeroed: those
    /// channels read exactly zero until trained; the others are untouched.
    pub fn with_zero_channels(mut self, channels: std::ops::Range<usize>) -> Self {
        let zero_rows = |w: Tensor<4>| {
            let [_, inputs, kh, kw] = w.dims();
            let zeros = Tensor::zeros([channels.len(), inputs, kh, kw], &w.device());
            w.slice_assign([channels.clone(), 0..inputs, 0..kh, 0..kw], zeros)
        };
        let out = &mut self.scratch.output_conv2.out;
        out.weight = replace_value(out.weight.clone(), zero_rows);
        out.bias = out.bias.take().map(|b| {
            replace_value(b, |b| {
                let zeros = Tensor::zeros([channels.len()], &b.device());
                b.slice_assign([channels.clone()], zeros)
            })
        });
        self
    }

    fn add_pos_embed(&self, x: Tensor<4>, image_aspect: f64) -> Tensor<4> {
        if !self.pos_embed {
            return x;
        }
        let [_, c, h, w] = x.dims();
        let embed = uv_sincos_embedding(c, [h, w], image_aspect, POS_EMBED_OMEGA, POS_EMBED_RATIO);
        let embed = ConstantSite::like(&x).tensor(embed, [1, c, h, w]);
        x + embed
    }

    /// `layer(i)`: layer `i`'s `[B, S, P', dim_in]` tokens (only the tapped layers are asked for); patches
    /// start at `patch_start_idx` and form a `grid = [rows, cols]` grid. `images`, `[B, S, 3, H, W]` in
    /// `[0, 1]`, are the frames the tokens come from; only a head with a pixel skip reads them.
    pub fn forward(
        &self,
        layer: impl Fn(usize) -> Tensor<4>,
        patch_start_idx: usize,
        [rows, cols]: [usize; 2],
        images: &Tensor<5>,
    ) -> DptOutput {
        let (height, width) = (rows * self.patch_size, cols * self.patch_size);
        let aspect = width as f64 / height as f64;
        let mut resized = Vec::with_capacity(4);
        let mut batch = 1;
        for (level, &index) in self.intermediate_layer_idx.iter().enumerate() {
            let x = layer(index);
            let [b, s, n, c] = x.dims();
            batch = b;
            let patches = self.norm.forward(x.narrow(2, patch_start_idx, n - patch_start_idx));
            let map = patches.reshape([b * s, rows * cols, c]).swap_dims(1, 2).reshape([b * s, c, rows, cols]);
            let projected = self.add_pos_embed(conv::conv2d(&self.projects[level], map), aspect);
            resized.push(self.resize_layers.forward(level, projected));
        }

        let sc = &self.scratch;
        let l1 = conv::conv2d(&sc.layer1_rn, resized[0].clone());
        let l2 = conv::conv2d(&sc.layer2_rn, resized[1].clone());
        let l3 = conv::conv2d(&sc.layer3_rn, resized[2].clone());
        let l4 = conv::conv2d(&sc.layer4_rn, resized[3].clone());
        let size = |t: &Tensor<4>| {
            let [_, _, h, w] = t.dims();
            [h, w]
        };
        let x = sc.refinenet4.forward(l4, None, Some(size(&l3)));
        let x = sc.refinenet3.forward(x, Some(l3), Some(size(&l2)));
        let x = sc.refinenet2.forward(x, Some(l2), Some(size(&l1)));
        let x = sc.refinenet1.forward(x, Some(l1), None);
        let fused = conv::conv2d(&sc.output_conv1, x);

        let head_in = self.add_pos_embed(bilinear_aligned(fused.clone(), [height, width]), aspect);
        let head_in = match &self.pixel_skip {
            Some(conv) => {
                let pixels = images.clone().cast(head_in.dtype()).reshape([head_in.dims()[0], 3, height, width]);
                head_in + conv::conv2d(conv, pixels)
            }
            None => head_in,
        };
        let out = conv::conv2d(&sc.output_conv2.out, relu(conv::conv2d(&sc.output_conv2.hidden, head_in.clone())));
        let [frames, channels, _, _] = out.dims();
        let raw = out.permute([0, 2, 3, 1]).reshape([batch, frames / batch, height, width, channels]);
        DptOutput { resized, fused, head_in, raw }
    }
}

impl DptHead {
    /// [`DptHead::forward`] followed by the head's activations.
    pub fn predict(
        &self,
        layer: impl Fn(usize) -> Tensor<4>,
        patch_start_idx: usize,
        grid: [usize; 2],
        images: &Tensor<5>,
    ) -> DptPrediction {
        let dpt = self.forward(layer, patch_start_idx, grid, images);
        let [activation, conf_activation] = self.activations;
        let (prediction, confidence) = activate_head(dpt.raw.clone(), activation, conf_activation);
        DptPrediction { dpt, prediction, confidence }
    }
}

fn activate(x: Tensor<5>, activation: HeadActivation) -> Tensor<5> {
    match activation {
        HeadActivation::Linear => x,
        HeadActivation::Exp => x.exp(),
        HeadActivation::Expp1 => x.exp().add_scalar(1.0),
        HeadActivation::Sigmoid => sigmoid(x),
        HeadActivation::InvLog => x.clone().sign() * (x.abs().exp().sub_scalar(1.0)),
    }
}

/// Splits a raw `[B, S, H, W, C]` head output into the activated prediction (channels `0..C-1`) and the
/// activated confidence (channel `C-1`, `[B, S, H, W]`).
pub fn activate_head(
    raw: Tensor<5>,
    activation: HeadActivation,
    conf_activation: HeadActivation,
) -> (Tensor<5>, Tensor<4>) {
    let c = raw.dims()[4];
    let prediction = activate(raw.clone().narrow(4, 0, c - 1), activation);
    let confidence = activate(raw.narrow(4, c - 1, 1), conf_activation).squeeze_dim::<4>(4);
    (prediction, confidence)
}
