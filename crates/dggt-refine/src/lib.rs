//! The single-step diffusion refiner of DGGT's last stage (Difix on sd-turbo): it cleans rendered frames —
//! ghosting, disocclusion gaps, holes — with one denoising step at timestep 199, optionally attending to a
//! reference input view.
//!
//! - [`vae`]: the autoencoder, its encoder keeping its down-block inputs and its decoder adding them back
//!   through skip convolutions; decoder LoRA merged at load ([`lora`]);
//! - [`unet`]: the SD 2.1-layout denoiser with its spatial transformers ([`transformer`]) and residual
//!   blocks ([`resnet`]);
//! - [`text_encoder`]: the CLIP text encoder for the fixed prompt, run once; [`tokenizer`]: its tokenizer;
//! - [`scheduler`]: the noise schedule and the step to the clean latent;
//! - [`refiner`]: the whole computation, and loading a diffusers model folder ([`config`], [`weights`], its
//!   files read piece by piece by the workspace's reader, `dggt_model::safetensors_file`) with a Difix checkpoint ([`checkpoint`]) over it; [`random`]: made-up weights at full size, for timing;
//! - [`precision`]: the float types of the UNet and the VAE;
//! - [`reference`]: which input view a rendered frame attends to in the reference-view mode.
//!
//! Tensors carry no backend type: the [`burn::tensor::Device`] the refiner is loaded on selects it.

pub mod checkpoint;
pub mod config;
mod error;
pub mod layers;
pub mod lora;
pub mod precision;
pub mod random;
pub mod reference;
pub mod refiner;
pub mod resnet;
pub mod scheduler;
pub mod text_encoder;
pub mod tokenizer;
pub mod trace;
pub mod transformer;
pub mod unet;
pub mod vae;
pub mod weights;

pub use error::{RefineError, UnknownName};
pub use precision::RefinerPrecision;
pub use reference::ReferenceView;
pub use refiner::{
    Latent, LoadReport, Refiner, RefinerParts, RefinerSpec, TIMESTEP, frame_from_interleaved, frame_to_interleaved,
};
pub use tokenizer::{DEFAULT_PROMPT, Prompt};
pub use trace::Trace;
