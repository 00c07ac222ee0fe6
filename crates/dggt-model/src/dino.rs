//! The DINOv2 ViT with registers that embeds image patches for the aggregator.
//!
//! Tokens: a 14x14 stride-14 convolution of the (already ImageNet-normalised) image gives one token per patch;
//! the cls token is prepended and the positional embedding added (its square grid resized to the patch grid
//! with PyTorch's antialiased bicubic kernel, see [`crate::resample`]); the register tokens, which get no
//! positional embedding, go right after cls: `[cls, registers, patches]`. Every block's output passed through
//! the final norm, patch tokens only, is what the network consumes (`get_intermediate_layers` over all blocks;
//! the last one equals `x_norm_patchtokens`).

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig};
use burn::tensor::{Device, Tensor};

use crate::block::{Block, BlockConfig};
use crate::config::DinoConfig;
use crate::constant::ConstantSite;
use crate::resample::{antialiased_bicubic_matrix_2d, sampling_step};

/// The convolutional patch embedding (`patch_embed.proj`).
#[derive(Module, Debug)]
pub struct PatchEmbed {
    pub proj: Conv2d,
}

#[derive(Module, Debug)]
pub struct Dino {
    pub patch_embed: PatchEmbed,
    pub cls_token: Param<Tensor<3>>,
    /// Masked-image-modelling token of the pretrained ViT; part of the checkpoint, unused at inference.
    pub mask_token: Param<Tensor<2>>,
    pub pos_embed: Param<Tensor<3>>,
    pub register_tokens: Param<Tensor<3>>,
    pub blocks: Vec<Block>,
    pub norm: LayerNorm,
    patch_size: usize,
    interpolate_offset: f64,
}

/// What one DINO pass yields.
#[derive(Debug, Clone)]
pub struct DinoOutput {
    /// `[frames, 1 + registers + patches, C]`: the tokens entering block 0.
    pub prepared_tokens: Tensor<3>,
    /// One entry per block: its output through the final norm, patch tokens only, `[frames, patches, C]`.
    pub layers: Vec<Tensor<3>>,
}

impl Dino {
    pub fn new(config: &DinoConfig, device: &Device) -> Self {
        let (c, p) = (config.embed_dim, config.patch_size);
        let grid = config.pos_embed_grid();
        let block = BlockConfig {
            dim: c,
            num_heads: config.num_heads,
            mlp_hidden: config.mlp_hidden(),
            norm_eps: config.norm_eps,
            qk_norm_eps: None,
        };
        assert!(config.interpolate_antialias, "only the antialiased positional-embedding resize is implemented");
        Self {
            patch_embed: PatchEmbed { proj: Conv2dConfig::new([3, c], [p, p]).with_stride([p, p]).init(device) },
            cls_token: Initializer::Zeros.init([1, 1, c], device),
            mask_token: Initializer::Zeros.init([1, c], device),
            pos_embed: Initializer::Zeros.init([1, 1 + grid * grid, c], device),
            register_tokens: Initializer::Zeros.init([1, config.num_register_tokens, c], device),
            blocks: (0..config.depth).map(|_| Block::new(block, device)).collect(),
            norm: LayerNormConfig::new(c).with_epsilon(config.norm_eps).init(device),
            patch_size: p,
            interpolate_offset: config.interpolate_offset,
        }
    }

    pub fn num_register_tokens(&self) -> usize {
        self.register_tokens.dims()[1]
    }

    /// The positional embedding for a `height x width` image, `[1, 1 + rows * cols, C]` (cls first, patches
    /// row-major). Returned unchanged when the grid is the trained square grid.
    pub fn interpolated_pos_embed(&self, height: usize, width: usize) -> Tensor<3> {
        let pos_embed = self.pos_embed.val();
        let [_, n, c] = pos_embed.dims();
        let trained = ((n - 1) as f64).sqrt() as usize;
        assert_eq!(trained * trained, n - 1, "pos_embed does not hold a square grid");
        let rows = height / self.patch_size;
        let cols = width / self.patch_size;
        if rows * cols == n - 1 && height == width {
            return pos_embed;
        }
        let (output, step) = if self.interpolate_offset != 0.0 {
            let factor = |cells: usize| (cells as f64 + self.interpolate_offset) / trained as f64;
            let (fy, fx) = (factor(rows), factor(cols));
            let output = [(trained as f64 * fy).floor() as usize, (trained as f64 * fx).floor() as usize];
            assert_eq!(output, [rows, cols], "interpolate_offset resize does not land on the patch grid");
            (output, [sampling_step(trained, rows, Some(fy)), sampling_step(trained, cols, Some(fx))])
        } else {
            ([rows, cols], [sampling_step(trained, rows, None), sampling_step(trained, cols, None)])
        };
        let matrix = antialiased_bicubic_matrix_2d([trained, trained], output, step);
        let matrix = ConstantSite::like(&pos_embed).tensor(matrix, [rows * cols, trained * trained]);
        let cls = pos_embed.clone().narrow(1, 0, 1);
        let grid = pos_embed.narrow(1, 1, n - 1).reshape([n - 1, c]);
        let resized = matrix.matmul(grid).unsqueeze::<3>();
        Tensor::cat(vec![cls, resized], 1)
    }

    /// Tokens entering block 0 for `[frames, 3, H, W]` normalised images: `[frames, 1 + R + patches, C]`.
    pub fn prepare_tokens(&self, images: Tensor<4>) -> Tensor<3> {
        let [frames, _, height, width] = images.dims();
        let patches = self.patch_embed.proj.forward(images).flatten::<3>(2, 3).swap_dims(1, 2);
        let c = patches.dims()[2];
        let cls = self.cls_token.val().expand([frames, 1, c]);
        let tokens = Tensor::cat(vec![cls, patches], 1) + self.interpolated_pos_embed(height, width);
        let registers = self.register_tokens.val().expand([frames, self.num_register_tokens(), c]);
        let n = tokens.dims()[1];
        Tensor::cat(vec![tokens.clone().narrow(1, 0, 1), registers, tokens.narrow(1, 1, n - 1)], 1)
    }

    /// Runs every block on `[frames, 3, H, W]` normalised images.
    pub fn forward(&self, images: Tensor<4>) -> DinoOutput {
        let prepared_tokens = self.prepare_tokens(images);
        let first_patch = 1 + self.num_register_tokens();
        let mut x = prepared_tokens.clone();
        let mut layers = Vec::with_capacity(self.blocks.len());
        for block in &self.blocks {
            x = block.forward(x, None);
            let n = x.dims()[1];
            layers.push(self.norm.forward(x.clone().narrow(1, first_patch, n - first_patch)));
        }
        DinoOutput { prepared_tokens, layers }
    }
}
