//! Differentiable 3D Gaussian rasterisation for dggt: the host reference implementation.
//!
//! DGGT renders its predicted Gaussians with gsplat's "classic" 3DGS rasteriser (pinhole, eps2d 0.3, near 0.01,
//! 16x16 tiles, alpha threshold 1/255, expected depth). This crate reproduces those semantics in plain Rust over
//! flat `f32` buffers, forward and hand-written backward, parallel with rayon and bit-deterministic. It is the
//! reference that CPU tensor backends call and that GPU kernels are tested against, so its buffers are the
//! structure-of-arrays layouts a kernel would use (shapes are documented on each type).
//!
//! The pipeline, one module per stage:
//!
//! 1. `covariance`: `Σ = R S Sᵀ Rᵀ` from `wxyz` quaternions and linear scales.
//! 2. `projection`: EWA projection into each view, culling with a [`CullReason`].
//! 3. `tiles`: kept Gaussians binned into screen tiles, sorted by depth.
//! 4. `composite`: front-to-back alpha compositing per pixel (4x4 blocks of pixels as SIMD lanes, `lanes`), and
//!    its backward pass.
//! 5. [`rasterize`] / [`rasterize_backward`] run the stages over a batch of views.
//!
//! Every threshold and default they use (alpha threshold, transmittance floor, guard band, box sigmas, near and
//! far planes, `eps2d`) is defined once in [`constants`], which the CubeCL kernels and `dggt-scene`'s culling
//! read too.
//!
//! On burn tensors: [`render`] checks typed tensor inputs and calls [`SplatOps`], a backend extension whose CPU
//! implementation runs the host pipeline above and whose autodiff implementation calls its backward pass. With the
//! `wgpu` or `cuda` feature the same op runs on burn's CubeCL backend: the pipeline's stages as CubeCL kernels on
//! the device, one kernel set for every CubeCL runtime, tested against this host implementation (see `op`).
//!
//! Sanitising (never NaN, never a panic): a Gaussian with any non-finite parameter, or one whose projected
//! covariance is not positive definite or overflows, is culled in that view and counted in [`CullStats`];
//! a quaternion shorter than [`QUAT_MIN_NORM`] is the identity rotation with zero gradient. Wrong buffer
//! lengths, invalid cameras or settings, and non-finite image gradients are a [`SplatError`].

mod backward;
mod blocks;
mod composite;
pub mod constants;
mod covariance;
mod cull;
mod error;
mod forward;
mod gaussians;
mod lanes;
// burn's NdArray backend is deprecated; the `ndarray` feature names it on purpose.
#[cfg_attr(feature = "ndarray", allow(deprecated))]
mod op;
mod projection;
mod render;
mod settings;
mod tiles;
mod view;

pub use backward::{GaussianGrads, ImageGrads, rasterize_backward};
pub use constants::QUAT_MIN_NORM;
pub use cull::{CullReason, CullStats};
pub use error::SplatError;
pub use forward::{Images, Rasterized, rasterize};
pub use gaussians::{Gaussians, Opacities};
#[cfg(any(feature = "wgpu", feature = "cuda"))]
pub use op::CubeForward;
pub use op::{HostForward, PACKED_EXTRA_CHANNELS, SplatGrads, SplatInputs, SplatKernels, SplatOps, SplatOutputs};
/// The device radix sort of tile intersections on host data, for tests.
#[cfg(any(feature = "wgpu", feature = "cuda"))]
#[doc(hidden)]
pub use op::{SortedIntersections, prefix_sums, sort_intersections};
pub use projection::Projection;
pub use render::{
    CameraTensors, GaussianTensors, OpacityTensor, RenderSettings, RenderTensors, render, render_with_stats,
};
pub use settings::{DepthStatistic, RasterSettings};
pub use tiles::TileBins;
pub use view::{PinholeView, ViewBatch};
