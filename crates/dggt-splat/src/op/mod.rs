//! The rasteriser as a burn backend extension, in two layers.
//!
//! - [`SplatOps`] is the operation tensors are dispatched through: the `#[backend_extension]` macro routes a
//!   call on burn's type-erased `Dispatch` backend to the backend the tensors live on, autodiff included. Its
//!   single method renders a whole batch of views in one call.
//! - [`SplatKernels`] is what a backend implements: a forward that can keep state for the backward pass, and
//!   that backward. Every `SplatKernels` backend gets `SplatOps` (forward only), and `Autodiff<B>` gets it with a
//!   hand-written backward for every `B: SplatKernels` (see `autodiff`). The saved state is the backend's own
//!   associated type, so the autodiff glue never sees a host buffer: the CPU backends keep host copies, the
//!   CubeCL backend keeps device buffers, and both slot into the same graph node.
//!
//! The implementations:
//!
//! - `host` (Flex, and NdArray with the `ndarray` feature): reads the tensors into host buffers and runs the host
//!   pipeline ([`rasterize`](crate::rasterize), [`rasterize_backward`](crate::rasterize_backward)); the outputs
//!   are bit-identical to it.
//! - `cube` (features `wgpu` / `cuda`): burn's `CubeBackend`, the one backend type of every CubeCL runtime, so a
//!   single set of CubeCL kernels serves wgpu (Vulkan, Metal, DX12) and CUDA. The stages of the host pipeline run
//!   as kernels on the device, in `f32`, with the host's rules and culling codes; the only read-back is the number
//!   of tile intersections per view (`V + 1` integers per call), which sizes the tile-list buffers and groups
//!   the views into batches that fit the device's buffer limit. Gradients are added
//!   with atomics (native `f32` atomic add where the device has it, compare-and-swap otherwise), so results agree
//!   with the host to float rounding rather than bit for bit.
//! - `fusion` (feature `fusion` with `wgpu` / `cuda`): `Fusion<CubeBackend>`, which is what burn's `Cube`
//!   dispatch type, and so `Device::wgpu(..)` / `Device::cuda(..)`, is when burn's `fusion` feature is on.
//!   Without it a CubeCL device dispatches to `CubeBackend` directly. The fused implementation resolves its
//!   inputs, runs the `cube` kernels eagerly and registers the results in the fusion stream.
//!
//! Outputs are packed so that autodiff tracks one tensor per call: `images` is `[V, H, W, K + 2]`, channels
//! `0..K` the colours, `K` the alpha and `K + 1` the expected depth (the meanings of [`Images`](crate::Images)).
//! The public wrapper in `render` slices it; the slices' gradients flow back into one packed gradient. The
//! statistics are integers of the backend's choice (`i64` on the CPU backends, `i32` on CubeCL).

mod autodiff;
#[cfg(any(feature = "wgpu", feature = "cuda"))]
mod cube;
#[cfg(all(any(feature = "wgpu", feature = "cuda"), feature = "fusion"))]
mod fusion;
mod host;

use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Backend, ExtensionType, backend_extension};
use dggt_geom::ImageSize;

use crate::settings::RasterSettings;

#[cfg(any(feature = "wgpu", feature = "cuda"))]
pub use cube::{CubeForward, SortedIntersections, prefix_sums, sort_intersections};
pub use host::HostForward;

/// Extra channels after the `K` colours in the packed image tensor: alpha, then depth.
pub const PACKED_EXTRA_CHANNELS: usize = 2;

/// The rasteriser on burn tensors (float tensors `f32`).
///
/// Inputs, `N` Gaussians and `V` views:
///
/// | tensor | shape |
/// |---|---|
/// | `means` | `[N, 3]` world coordinates |
/// | `quats` | `[N, 4]` rotations, `w x y z` |
/// | `scales` | `[N, 3]` linear standard deviations |
/// | `opacities` | `[N]` shared or `[V, N]` per view |
/// | `colors` | `[N, K]` |
/// | `background` | `[K]` |
/// | `viewmats` | `[V, 4, 4]` world-to-camera |
/// | `intrinsics` | `[V, 3, 3]` pinhole `K` |
///
/// `settings.background` is ignored (the background is the tensor). Returns the packed images
/// `[V, H, W, K + 2]` (see the module documentation) and the culling statistics `[V, CullStats::COUNTS]`
/// (integers, rows as [`CullStats::to_counts`](crate::CullStats::to_counts)).
///
/// Under autodiff, gradients reach `means`, `quats`, `scales`, `opacities`, `colors` and `background`; the
/// cameras are constants.
///
/// # Panics
///
/// On inputs the rasteriser refuses (wrong shapes, non-finite cameras, invalid settings, non-finite image
/// gradients in the backward pass). [`render`](crate::render) checks shapes, element types and settings first
/// and reports them as [`SplatError`](crate::SplatError)s.
#[backend_extension(
    Flex,
    NdArray: cfg(feature = "ndarray"),
    // burn's `Cube` type: `CubeBackend`, or `Fusion<CubeBackend>` when burn's `fusion` feature is on.
    Cube: cfg(any(feature = "wgpu", feature = "cuda")),
    Autodiff
)]
pub trait SplatOps: Backend {
    fn splat_render(
        #[extension_type] inputs: SplatInputs<Self>,
        settings: RasterSettings,
        size: ImageSize,
    ) -> (FloatTensor<Self>, IntTensor<Self>);
}

/// The inputs of one call as backend primitives, shaped as documented on [`SplatOps`].
#[derive(Debug, Clone, ExtensionType)]
pub struct SplatInputs<B: Backend> {
    pub means: FloatTensor<B>,
    pub quats: FloatTensor<B>,
    pub scales: FloatTensor<B>,
    pub opacities: FloatTensor<B>,
    pub colors: FloatTensor<B>,
    pub background: FloatTensor<B>,
    pub viewmats: FloatTensor<B>,
    pub intrinsics: FloatTensor<B>,
}

/// What the forward pass returns: packed images `[V, H, W, K + 2]` and statistics `[V, CullStats::COUNTS]`.
#[derive(Debug, Clone)]
pub struct SplatOutputs<B: Backend> {
    pub images: FloatTensor<B>,
    pub stats: IntTensor<B>,
}

/// Gradients of the differentiable inputs, shaped like them (`opacities` `[N]` or `[V, N]` as given).
#[derive(Debug, Clone)]
pub struct SplatGrads<B: Backend> {
    pub means: FloatTensor<B>,
    pub quats: FloatTensor<B>,
    pub scales: FloatTensor<B>,
    pub opacities: FloatTensor<B>,
    pub colors: FloatTensor<B>,
    pub background: FloatTensor<B>,
}

/// A backend's implementation of the rasteriser: forward, and backward from what the forward saved.
pub trait SplatKernels: Backend {
    /// What the backward pass needs, kept alive by the autodiff graph between the two passes.
    type Saved: Clone + Send + Sync + core::fmt::Debug + 'static;

    /// Renders and returns the state for [`splat_backward`](Self::splat_backward).
    fn splat_forward_saved(
        inputs: SplatInputs<Self>,
        settings: &RasterSettings,
        size: ImageSize,
    ) -> (SplatOutputs<Self>, Self::Saved);

    /// Renders without keeping state (when no input requires a gradient). Backends whose saved state costs
    /// more than dropping it override this.
    fn splat_forward(inputs: SplatInputs<Self>, settings: &RasterSettings, size: ImageSize) -> SplatOutputs<Self> {
        Self::splat_forward_saved(inputs, settings, size).0
    }

    /// Gradients of all differentiable inputs given the gradient of the packed images `[V, H, W, K + 2]`.
    fn splat_backward(saved: Self::Saved, grad_images: FloatTensor<Self>) -> SplatGrads<Self>;
}

impl<B: SplatKernels> SplatOps for B {
    fn splat_render(
        inputs: SplatInputs<Self>,
        settings: RasterSettings,
        size: ImageSize,
    ) -> (FloatTensor<Self>, IntTensor<Self>) {
        let outputs = B::splat_forward(inputs, &settings, size);
        (outputs.images, outputs.stats)
    }
}
