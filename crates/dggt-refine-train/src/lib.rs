//! Training the single-step diffusion refiner (Difix on sd-turbo) on pairs of a rendered frame with
//! reconstruction artifacts and its ground truth, as the Difix paper does:
//!
//! - [`pair`]: one pair (render, target, reference) as host images, and the view a rendered one shows;
//! - [`pairs`]: the training and held-out pairs, and the synthetic degradations used where no renders exist;
//! - [`model`]: the refiner made trainable: the UNet trained fully, the decoder's LoRA kept as separate
//!   low-rank factors over its frozen weights, its skip convolutions trained, the encoder frozen;
//! - [`loss`]: `l2 · L2 + lpips · LPIPS + gram · Gram(VGG-16)`;
//! - [`render_pairs`]: pairs rendered by a trained reconstruction run at non-input frames, with an input view
//!   as the reference; [`pair_files`]: their files, written and read a pair at a time as training draws them;
//! - [`fresh`]: the starting skip convolutions and LoRA when only the base model (sd-turbo) is given;
//! - [`difix_checkpoint`]: the trained weights as a Difix checkpoint (LoRA factors in peft's names) that the
//!   refiner's loader merges, written to and read from a safetensors file;
//! - [`trainer`]: the loop, on `dggt-run`'s AdamW, checkpoints and exact resume, with the PSNR of the
//!   refined held-out pairs as its metric; [`records`]: what it reports of each step and validation pass, and
//!   [`watch`]: what it hands an observer;
//! - [`config`]: the run's TOML configuration, defaulting to the paper's settings.

pub mod config;
pub mod difix_checkpoint;
mod error;
pub mod fresh;
pub mod loss;
pub mod model;
pub mod pair;
pub mod pair_files;
pub mod pairs;
pub mod records;
pub mod render_pairs;
pub mod trainer;
pub mod watch;

pub use config::RefineTrainConfig;
pub use error::{PairKind, RefineTrainError};
pub use trainer::RefineTrainer;
pub use watch::{RefineWatcher, RefinedPicture};
