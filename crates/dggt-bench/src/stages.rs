//! The reconstruction split into the stages the benchmark times, each computing exactly what the pipeline
//! computes:
//!
//! - [`backbone`]: the aggregator (patch embedding and alternating attention) over all frames;
//! - [`heads`]: the camera head and the dense heads (depth, dynamic, Gaussian) a few frames at a time, as
//!   [`dggt_infer::forward_chunked`] runs them (outputs in f32);
//! - [`Scene4d::assemble`] (called by the runner): the static union faded to the target time, the nearest
//!   view's dynamic Gaussians and the culling;
//! - [`rasterise`]: the assembled Gaussians over the sky, as [`Scene4d::render`] composites them.
//!
//! A device may run work asynchronously (the GPU backends), so [`settle`] blocks until a stage's outputs are
//! computed before its clock stops. The runner times the backbone in a run of its own and the backbone and
//! heads together (the heads' time is the difference): waiting on the aggregator's outputs before the heads
//! ran made the heads' outputs NaN on wgpu with burn 0.22.1.

use burn::tensor::Tensor;
use dggt_infer::{MotionPath, Prediction, heads_chunked};
use dggt_model::Dggt;
use dggt_model::aggregator::AggregatorOutput;
use dggt_model::host::host_f32;
use dggt_scene::Scene4d;
use dggt_scene::{AssembledGaussians, TargetView};

use crate::error::BenchError;

/// Blocks until `tensor` is computed, by reading one of its values back. (A device-wide
/// [`Device::sync`] between stages made later outputs non-finite on wgpu in burn 0.22.1; reading a value back
/// waits for the work that produces the tensor without disturbing what is still queued.)
pub fn settle<const D: usize>(tensor: &Tensor<D>) -> Result<(), BenchError> {
    if tensor.shape().num_elements() == 0 {
        return Ok(());
    }
    host_f32(tensor.clone().sum(), "a stage's output")?;
    Ok(())
}

/// The aggregator on `images` (`[1, S, 3, H, W]`, RGB in `[0, 1]`, in the model's float type).
pub fn backbone(model: &Dggt, images: Tensor<5>) -> Result<AggregatorOutput, BenchError> {
    Ok(model.aggregator.forward(images)?)
}

/// The camera head and the dense heads on `aggregator`'s tokens, the dense heads `chunk` frames at a time
/// ([`heads_chunked`], the reconstruction's own); `images` are the backbone's input. Outputs are f32.
pub fn heads(
    model: &Dggt,
    aggregator: AggregatorOutput,
    images: Tensor<5>,
    chunk: usize,
    motion: MotionPath,
) -> Result<Prediction, BenchError> {
    Ok(heads_chunked(model, aggregator, images, chunk, motion)?)
}

/// One rendered target view: `[H, W, 3]` colours (on the host, interleaved, not clamped).
pub struct Rasterised {
    pub rgb: Vec<f32>,
    /// Whether the sky was rendered behind the view.
    pub sky_rendered: bool,
}

/// Rasterises Gaussians `scene` assembled for `target` and composites them over its sky (black without),
/// exactly as [`Scene4d::render`] does after its assembly step.
pub fn rasterise(
    scene: &Scene4d,
    assembled: &AssembledGaussians,
    target: &TargetView,
) -> Result<Rasterised, BenchError> {
    let view = scene.render_assembled(assembled, target)?;
    let sky_rendered = view.sky.is_some();
    let rgb = host_f32(view.rgb, "render")?;
    Ok(Rasterised { rgb, sky_rendered })
}
