//! The `dggt-losses` integration tests in one binary (one link of the dependency tree instead of one per file);
//! `gradients_f64` keeps its own process, whose flex device it sets to f64 before any other use.

#[path = "../common/mod.rs"]
mod common;

mod gradients;
mod lpips_vgg;
mod parity;
mod stability;
mod weights;
