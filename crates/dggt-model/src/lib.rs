//! The DGGT network on burn: a VGGT-style feedforward model that predicts, from a few unposed frames of a
//! driving scene, per-frame cameras and dense per-pixel maps.
//!
//! Built so far, each matched against the release's own outputs (`dggt-parity`'s `tests/parity/parity.rs`):
//! - [`config`]: every size, read from a parity `config.json` or from presets (`tiny`, `vggt_1b`, `dggt`);
//! - [`dino`]: the DINOv2 patch embedding with its antialiased positional-embedding resize ([`resample`]);
//! - [`aggregator`]: alternating frame/global attention with qk-norm and 2D RoPE ([`rope`]);
//! - [`camera_head`]: iterative `absT_quaR_FoV` pose refinement;
//! - [`dpt`]: the DPT dense head with its UV positional embedding ([`uv_embed`]): depth, point, Gaussian
//!   ([`gaussian_maps`]), instance (dynamic) and semantic heads;
//! - [`weights`]: loading checkpoints (`.safetensors`, `.pt`) with the release's PyTorch key names; the
//!   full-size presets are checked name by name and shape by shape against the released checkpoints' key
//!   lists (`tests/model/checkpoint_keys.rs`).
//!
//! - [`sky`]: the sky model's Gaussians and their colours sampled from the input views;
//! - [`lifespan`]: frame times, the static/dynamic opacity split and the lifespan decay;
//! - [`safetensors_file`]: the workspace's one safetensors reader (header, shapes, types, tensors as `f32`);
//! - [`seeded`]: fresh weights drawn from a seed, one caller at a time (the backend's generator is global);
//! - [`host`]: device tensors copied to the host as `f32`, with an error naming the tensor.
//!
//! The network stops at its maps: placing and rendering Gaussians is `dggt-scene`'s, and running a folder of
//! reference vectors against the release (`dggt parity`) is `dggt-parity`'s.
//!
//! Not built: the tracker head (never run by DGGT).
//!
//! Tensors carry no backend type: the [`burn::tensor::Device`] a model is built on selects it.

pub mod aggregator;
pub mod attention;
pub mod block;
pub mod camera_head;
pub mod config;
pub mod constant;
pub mod conv;
pub mod dino;
pub mod dpt;
mod error;
pub mod gaussian_maps;
pub mod host;
pub mod leaf;
pub mod lifespan;
pub mod mlp;
pub mod model;
pub mod resample;
pub mod rope;
pub mod safetensors_file;
pub mod seeded;
pub mod sky;
pub mod uv_embed;
pub mod weights;

pub use config::{ModelConfig, Preset};
pub use error::ModelError;
pub use model::{Dggt, DggtOutput, ExtraHeads, GaussianOutput};
