//! The alternating-attention aggregator: DINO patch tokens of every frame, prefixed per frame with a camera
//! token and register tokens, refined by `depth` pairs of frame-wise and global (all frames) attention blocks.
//!
//! Special tokens hold two learned variants: index 0 for the first frame, index 1 for every other frame.
//! Per-frame token order is `[camera, registers, patches]`. Frame attention sees `[B*S, P', C]`, global
//! attention `[B, S*P', C]` with the per-frame RoPE grid repeated for every frame; there is no time embedding.
//! The outputs the heads consume are kept per layer: `output_list[i] = [frame_i | global_i]` (2C),
//! `dino_token_list[i]` (the DINO block-`i` patch tokens with the aggregator's special tokens prepended) and
//! `output_with_dino_tokens(i) = [dino_token_list[0] | frame_i | global_i]` (3C; block 0 whatever `i`, as the
//! release computes it).

use burn::module::{Module, Param};
use burn::nn::Initializer;
use burn::tensor::{Device, Tensor};

use crate::block::{Block, BlockConfig};
use crate::config::AggregatorConfig;
use crate::constant::ConstantSite;
use crate::dino::{Dino, DinoOutput};
use crate::error::ModelError;
use crate::rope::RopeTable;

#[derive(Module, Debug)]
pub struct Aggregator {
    pub patch_embed: Dino,
    /// `[1, 2, 1, C]`: variant 0 for frame 0, variant 1 for the others.
    pub camera_token: Param<Tensor<4>>,
    /// `[1, 2, R, C]`.
    pub register_token: Param<Tensor<4>>,
    pub frame_blocks: Vec<Block>,
    pub global_blocks: Vec<Block>,
    patch_size: usize,
    head_dim: usize,
    rope_freq: f64,
    mean: [f64; 3],
    std: [f64; 3],
}

/// Everything the heads read from one aggregator pass. Token tensors are `[B, S, P', C]` with
/// `P' = patch_start_idx + rows * cols`.
#[derive(Debug, Clone)]
pub struct AggregatorOutput {
    /// The DINO pass over the `B*S` frames.
    pub dino: DinoOutput,
    /// `[frame_i | global_i]` per layer, `[B, S, P', 2C]`.
    pub output_list: Vec<Tensor<4>>,
    /// DINO block-`i` patch tokens behind the aggregator's special tokens, `[B, S, P', C]`.
    pub dino_token_list: Vec<Tensor<4>>,
    /// Index of the first patch token.
    pub patch_start_idx: usize,
    /// Patch grid `[rows, cols]`.
    pub grid: [usize; 2],
}

impl AggregatorOutput {
    /// `[dino_token_list[0] | frame_i | global_i]`, `[B, S, P', 3C]` (the Gaussian head's input).
    pub fn output_with_dino_tokens(&self, layer: usize) -> Tensor<4> {
        Tensor::cat(vec![self.dino_token_list[0].clone(), self.output_list[layer].clone()], 3)
    }
}

impl Aggregator {
    pub fn new(config: &AggregatorConfig, device: &Device) -> Self {
        let c = config.embed_dim;
        let block = BlockConfig {
            dim: c,
            num_heads: config.num_heads,
            mlp_hidden: config.mlp_hidden(),
            norm_eps: config.block_norm_eps,
            qk_norm_eps: config.qk_norm.then_some(config.qk_norm_eps),
        };
        let blocks = || (0..config.depth).map(|_| Block::new(block, device)).collect();
        Self {
            patch_embed: Dino::new(&config.dino, device),
            camera_token: Initializer::Zeros.init([1, 2, 1, c], device),
            register_token: Initializer::Zeros.init([1, 2, config.num_register_tokens, c], device),
            frame_blocks: blocks(),
            global_blocks: blocks(),
            patch_size: config.patch_size,
            head_dim: config.head_dim(),
            rope_freq: config.rope_freq,
            mean: config.image_normalization.mean,
            std: config.image_normalization.std,
        }
    }

    /// The camera and register tokens of every frame, `[B, S, 1 + R, C]`.
    pub fn special_tokens(&self, batch: usize, frames: usize) -> Tensor<4> {
        let tokens = Tensor::cat(vec![self.camera_token.val(), self.register_token.val()], 2);
        let [_, _, n, c] = tokens.dims();
        let first = tokens.clone().narrow(1, 0, 1).expand([batch, 1, n, c]);
        if frames == 1 {
            return first;
        }
        let others = tokens.narrow(1, 1, 1).expand([batch, frames - 1, n, c]);
        Tensor::cat(vec![first, others], 1)
    }

    /// `images`: `[B, S, 3, H, W]` RGB in `[0, 1]`, `H` and `W` multiples of the patch size.
    pub fn forward(&self, images: Tensor<5>) -> Result<AggregatorOutput, ModelError> {
        let [b, s, _, h, w] = images.dims();
        let p = self.patch_size;
        if h % p != 0 || w % p != 0 {
            return Err(ModelError::ImageSize { height: h, width: w, patch: p });
        }
        // The images enter in the parameters' float type (f32 images drive a network cast to bf16 or f16).
        let images = images.cast(self.camera_token.val().dtype());
        let site = ConstantSite::like(&images);
        let channel = |v: [f64; 3]| site.tensor(v.map(|x| x as f32).to_vec(), [1, 1, 3, 1, 1]);
        let normalised = (images - channel(self.mean)) / channel(self.std);
        let dino = self.patch_embed.forward(normalised.reshape([b * s, 3, h, w]));
        let patches = dino.layers.last().expect("DINO has at least one block").clone();
        let [_, num_patches, c] = patches.dims();

        let special = self.special_tokens(b, s);
        let start = special.dims()[2];
        let per_frame = start + num_patches;
        let grid = [h / p, w / p];
        let frame_rope =
            (self.rope_freq > 0.0).then(|| RopeTable::for_frame(start, grid, self.head_dim, self.rope_freq, &site));
        let global_rope = frame_rope.as_ref().map(|r| r.repeat_frames(s));

        let mut tokens = Tensor::cat(vec![special.clone(), patches.reshape([b, s, num_patches, c])], 2);
        let mut output_list = Vec::with_capacity(self.frame_blocks.len());
        for (frame_block, global_block) in self.frame_blocks.iter().zip(&self.global_blocks) {
            let frame = frame_block
                .forward(tokens.reshape([b * s, per_frame, c]), frame_rope.as_ref())
                .reshape([b, s, per_frame, c]);
            let global = global_block
                .forward(frame.clone().reshape([b, s * per_frame, c]), global_rope.as_ref())
                .reshape([b, s, per_frame, c]);
            output_list.push(Tensor::cat(vec![frame, global.clone()], 3));
            tokens = global;
        }

        let dino_token_list = dino
            .layers
            .iter()
            .map(|layer| Tensor::cat(vec![special.clone(), layer.clone().reshape([b, s, num_patches, c])], 2))
            .collect();
        Ok(AggregatorOutput { dino, output_list, dino_token_list, patch_start_idx: start, grid })
    }
}
