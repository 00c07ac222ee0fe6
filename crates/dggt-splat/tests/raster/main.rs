//! Integration tests of the rasteriser: parity with gsplat, finite differences, per-view opacities,
//! robustness and determinism, empty scenes, the burn tensor op against the host functions, and (feature
//! `wgpu`) the CubeCL kernels against the host.

#[cfg(feature = "wgpu")]
mod batches;
#[cfg(feature = "wgpu")]
mod cube;
mod empty;
mod finite_difference;
mod median_depth;
mod parity;
mod per_view;
#[cfg(feature = "wgpu")]
mod radix;
mod scenes;
mod stress;
mod tensor_op;
#[cfg(feature = "wgpu")]
mod tile_cubes;
