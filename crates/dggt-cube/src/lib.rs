//! CubeCL helpers shared by the workspace's GPU kernels (the rasteriser's and the flow head's attention), so that
//! each kernel set keeps to its own arithmetic:
//!
//! - [`atomic`]: adding `f32` values into a buffer many units write at once (gradients gathered from scattered
//!   reads), with a native atomic where the device has one and a compare-and-swap loop on the bits otherwise.
//! - [`fusion`] (feature `fusion`): what an op whose sizes depend on its data does under burn's kernel fusion:
//!   resolve its inputs to device tensors, run its kernels eagerly, register the results in the fusion stream.
//!
//! Both need a CubeCL runtime: features `wgpu` or `cuda` (without either the crate is empty).

#[cfg(any(feature = "wgpu", feature = "cuda"))]
pub mod atomic;
#[cfg(all(any(feature = "wgpu", feature = "cuda"), feature = "fusion"))]
pub mod fusion;
