//! [`SplatKernels`] for the CPU backends: read the input tensors into flat host buffers, run [`rasterize`] /
//! [`rasterize_backward`] once for the whole batch, and write the results back as tensors.
//!
//! The saved state is a [`HostForward`]: host copies of every input plus the [`Rasterized`] result, behind an
//! `Arc` so that the autodiff graph can clone it for free.

use std::fmt;
use std::sync::Arc;

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Flex, TensorMetadata};
use burn::tensor::{TensorData, try_read_sync};
use dggt_geom::ImageSize;

use super::{PACKED_EXTRA_CHANNELS, SplatGrads, SplatInputs, SplatKernels, SplatOutputs};
use crate::backward::{ImageGrads, rasterize_backward};
use crate::cull::CullStats;
use crate::forward::{Rasterized, rasterize};
use crate::gaussians::{Gaussians, Opacities};
use crate::settings::{DepthStatistic, RasterSettings};
use crate::view::ViewBatch;

/// What the host backward pass reads: the inputs of the forward pass as host buffers and its result.
///
/// Memory, for `N` Gaussians with `K` channels and `V` views of `P` pixels: the inputs
/// (`N · (10 + K)` values, plus `V · N` for per-view opacities), the images (`V · P · (K + 2)`), per-pixel
/// transmittance and list ends (`2 · V · P`), the projection (about `13 · V · N`) and the tile lists
/// (two `u32` per tile intersection). Freed when the graph node is consumed or dropped.
pub struct HostForward {
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    opacities: Opacities<Vec<f32>>,
    colors: Vec<f32>,
    channels: usize,
    views: ViewBatch,
    /// With the background read from its tensor.
    settings: RasterSettings,
    forward: Rasterized,
}

impl HostForward {
    fn gaussians(&self) -> Gaussians<'_> {
        Gaussians::new(&self.means, &self.quats, &self.scales, self.opacities.as_slices(), &self.colors, self.channels)
            .expect("buffers were checked by the forward pass")
    }
}

impl fmt::Debug for HostForward {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HostForward")
            .field("gaussians", &(self.means.len() / 3))
            .field("channels", &self.channels)
            .field("views", &self.views.len())
            .field("size", &self.views.size())
            .finish_non_exhaustive()
    }
}

/// Reads an `f32` tensor into a host vector, waiting for the backend.
fn read<B: Backend>(tensor: FloatTensor<B>, what: &str) -> Vec<f32> {
    try_read_sync(B::float_into_data(tensor))
        .unwrap_or_else(|| panic!("splat: reading `{what}` cannot complete synchronously on this backend"))
        .unwrap_or_else(|e| panic!("splat: reading `{what}` failed: {e:?}"))
        .try_into_vec::<f32>()
        .unwrap_or_else(|e| panic!("splat: `{what}` is not an f32 tensor: {e:?}"))
}

fn write<B: Backend>(values: Vec<f32>, shape: Vec<usize>, device: &B::Device) -> FloatTensor<B> {
    B::float_from_data(TensorData::new(values, shape), device)
}

fn forward_saved<B: Backend>(
    inputs: SplatInputs<B>,
    settings: &RasterSettings,
    size: ImageSize,
) -> (SplatOutputs<B>, Arc<HostForward>) {
    let device = inputs.means.device();
    let channels = inputs.colors.shape()[1];
    let per_view = inputs.opacities.shape().num_dims() == 2;
    let opacities = read::<B>(inputs.opacities, "opacities");
    let opacities = if per_view { Opacities::PerView(opacities) } else { Opacities::Shared(opacities) };
    let (means, quats, scales, colors) = (
        read::<B>(inputs.means, "means"),
        read::<B>(inputs.quats, "quats"),
        read::<B>(inputs.scales, "scales"),
        read::<B>(inputs.colors, "colors"),
    );
    let settings = RasterSettings { background: Some(read::<B>(inputs.background, "background")), ..settings.clone() };
    let views = ViewBatch::from_matrices(
        &read::<B>(inputs.viewmats, "viewmats"),
        &read::<B>(inputs.intrinsics, "intrinsics"),
        size,
    )
    .unwrap_or_else(|e| panic!("splat: {e}"));
    let forward = Gaussians::new(&means, &quats, &scales, opacities.as_slices(), &colors, channels)
        .and_then(|gaussians| rasterize(&gaussians, &views, &settings))
        .unwrap_or_else(|e| panic!("splat: {e}"));

    let (height, width) = (size.height as usize, size.width as usize);
    let images = write::<B>(
        pack(&forward, channels),
        vec![views.len(), height, width, channels + PACKED_EXTRA_CHANNELS],
        &device,
    );
    let counts: Vec<i64> = forward.stats.iter().flat_map(|s| s.to_counts()).map(|c| c as i64).collect();
    let stats = B::int_from_data(TensorData::new(counts, [views.len(), CullStats::COUNTS]), &device);
    let saved = HostForward { means, quats, scales, opacities, colors, channels, views, settings, forward };
    (SplatOutputs { images, stats }, Arc::new(saved))
}

fn backward<B: Backend>(saved: &HostForward, grad_images: FloatTensor<B>) -> SplatGrads<B> {
    let device = grad_images.device();
    let channels = saved.channels;
    let (colors, alpha, depth) = unpack(&read::<B>(grad_images, "image gradient"), channels);
    // A median depth is detached by `render`: its channel of the gradient is zero, and the backward takes none.
    let depth = match saved.settings.depth {
        DepthStatistic::Expected => Some(depth.as_slice()),
        DepthStatistic::Median => None,
    };
    let image_grads = ImageGrads { colors: Some(colors.as_slice()), alpha: Some(alpha.as_slice()), depth };
    let grads = rasterize_backward(&saved.gaussians(), &saved.views, &saved.settings, &saved.forward, &image_grads)
        .unwrap_or_else(|e| panic!("splat backward: {e}"));
    let count = saved.means.len() / 3;
    let opacity_shape = match &grads.opacities {
        Opacities::Shared(_) => vec![count],
        Opacities::PerView(_) => vec![saved.views.len(), count],
    };
    let opacities = match grads.opacities {
        Opacities::Shared(values) | Opacities::PerView(values) => values,
    };
    SplatGrads {
        means: write::<B>(grads.means, vec![count, 3], &device),
        quats: write::<B>(grads.quats, vec![count, 4], &device),
        scales: write::<B>(grads.scales, vec![count, 3], &device),
        opacities: write::<B>(opacities, opacity_shape, &device),
        colors: write::<B>(grads.colors, vec![count, channels], &device),
        background: write::<B>(grads.background, vec![channels], &device),
    }
}

/// Interleaves colours, alpha and depth per pixel: `[V, H, W, K + 2]`.
fn pack(forward: &Rasterized, channels: usize) -> Vec<f32> {
    let images = &forward.images;
    let mut packed = Vec::with_capacity(images.alpha.len() * (channels + PACKED_EXTRA_CHANNELS));
    for (pixel, color) in images.colors.chunks_exact(channels).enumerate() {
        packed.extend_from_slice(color);
        packed.push(images.alpha[pixel]);
        packed.push(images.depth[pixel]);
    }
    packed
}

/// The inverse of [`pack`]: colours `[V, H, W, K]`, alpha and depth `[V, H, W]`.
fn unpack(packed: &[f32], channels: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let stride = channels + PACKED_EXTRA_CHANNELS;
    let pixels = packed.len() / stride;
    let (mut colors, mut alpha, mut depth) =
        (Vec::with_capacity(pixels * channels), Vec::with_capacity(pixels), Vec::with_capacity(pixels));
    for pixel in packed.chunks_exact(stride) {
        colors.extend_from_slice(&pixel[..channels]);
        alpha.push(pixel[channels]);
        depth.push(pixel[channels + 1]);
    }
    (colors, alpha, depth)
}

/// Implements [`SplatKernels`] for a CPU backend with the host rasteriser.
macro_rules! host_kernels {
    ($backend:ty) => {
        impl SplatKernels for $backend {
            type Saved = Arc<HostForward>;

            fn splat_forward_saved(
                inputs: SplatInputs<Self>,
                settings: &RasterSettings,
                size: ImageSize,
            ) -> (SplatOutputs<Self>, Self::Saved) {
                forward_saved::<Self>(inputs, settings, size)
            }

            fn splat_backward(saved: Self::Saved, grad_images: FloatTensor<Self>) -> SplatGrads<Self> {
                backward::<Self>(&saved, grad_images)
            }
        }
    };
}

host_kernels!(Flex);
#[cfg(feature = "ndarray")]
host_kernels!(burn::backend::NdArray);
