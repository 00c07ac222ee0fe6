//! [`SplatKernels`] for burn's fused CubeCL backend, `Fusion<CubeBackend>`: what a wgpu or CUDA device
//! dispatches to when burn's `fusion` feature is on.
//!
//! The rasteriser's intersection count depends on the data, so the call cannot be recorded lazily into a
//! fusion stream: each pass runs the CubeCL kernels of [`CubeBackend`] eagerly between `dggt_cube::fusion`'s
//! resolve and publish. The saved state is the unfused backend's, device buffers only.

use std::sync::Arc;

use burn::backend::fusion::{Fusion, FusionTensor};
use burn::backend::tensor::FloatTensor;
use burn_cubecl::CubeBackend;
use burn_cubecl::tensor::CubeTensor;
use dggt_cube::fusion::{self, Runtime, TensorKind, publish};
use dggt_geom::ImageSize;

use super::cube::CubeForward;
use super::{SplatGrads, SplatInputs, SplatKernels, SplatOutputs};
use crate::settings::RasterSettings;

type Fused = Fusion<CubeBackend>;

/// The device tensor behind a fused float tensor, once every operation producing it has run.
fn resolve(tensor: FusionTensor<Runtime>) -> CubeTensor {
    fusion::resolve(tensor, TensorKind::Float)
}

fn resolve_inputs(inputs: SplatInputs<Fused>) -> SplatInputs<CubeBackend> {
    SplatInputs {
        means: resolve(inputs.means),
        quats: resolve(inputs.quats),
        scales: resolve(inputs.scales),
        opacities: resolve(inputs.opacities),
        colors: resolve(inputs.colors),
        background: resolve(inputs.background),
        viewmats: resolve(inputs.viewmats),
        intrinsics: resolve(inputs.intrinsics),
    }
}

impl SplatKernels for Fused {
    type Saved = Arc<CubeForward>;

    fn splat_forward_saved(
        inputs: SplatInputs<Self>,
        settings: &RasterSettings,
        size: ImageSize,
    ) -> (SplatOutputs<Self>, Self::Saved) {
        let (outputs, saved) = CubeBackend::splat_forward_saved(resolve_inputs(inputs), settings, size);
        (
            SplatOutputs {
                images: publish(outputs.images, TensorKind::Float),
                stats: publish(outputs.stats, TensorKind::Int),
            },
            saved,
        )
    }

    fn splat_backward(saved: Self::Saved, grad_images: FloatTensor<Self>) -> SplatGrads<Self> {
        let grads = CubeBackend::splat_backward(saved, resolve(grad_images));
        SplatGrads {
            means: publish(grads.means, TensorKind::Float),
            quats: publish(grads.quats, TensorKind::Float),
            scales: publish(grads.scales, TensorKind::Float),
            opacities: publish(grads.opacities, TensorKind::Float),
            colors: publish(grads.colors, TensorKind::Float),
            background: publish(grads.background, TensorKind::Float),
        }
    }
}
