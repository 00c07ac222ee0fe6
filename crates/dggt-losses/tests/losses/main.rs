//! The `dggt-losses` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod gradients;
mod gradients_f64;
mod lpips_vgg;
mod parity;
mod stability;
mod weights;
