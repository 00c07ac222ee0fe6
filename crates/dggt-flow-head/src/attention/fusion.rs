//! [`AttentionKernels`] for burn's fused CubeCL backend, `Fusion<CubeBackend>` (a wgpu or CUDA device when burn's
//! `fusion` feature is on): the inputs resolved, the `cube` kernels run eagerly, the results published in the
//! fusion stream (`dggt_cube::fusion`). The saved state is the unfused backend's.

use burn::backend::fusion::Fusion;
use burn::backend::tensor::FloatTensor;
use burn_cubecl::CubeBackend;
use dggt_cube::fusion::{TensorKind, publish, resolve};

use super::cube::CubeCall;
use super::{AttentionGrads, AttentionInputs, AttentionKernels};

impl AttentionKernels for Fusion<CubeBackend> {
    type Saved = CubeCall;

    fn attention_forward(inputs: AttentionInputs<Self>) -> (FloatTensor<Self>, Self::Saved) {
        let float = |tensor| resolve(tensor, TensorKind::Float);
        let resolved = AttentionInputs {
            offsets: float(inputs.offsets),
            rows: resolve(inputs.rows, TensorKind::Int),
            keys_values: float(inputs.keys_values),
            encoder_weight: float(inputs.encoder_weight),
            encoder_bias: float(inputs.encoder_bias),
            queries: float(inputs.queries),
            turned: float(inputs.turned),
        };
        let (out, saved) = CubeBackend::attention_forward(resolved);
        (publish(out, TensorKind::Float), saved)
    }

    fn attention_backward(saved: Self::Saved, grad_out: FloatTensor<Self>) -> AttentionGrads<Self> {
        let grads = CubeBackend::attention_backward(saved, resolve(grad_out, TensorKind::Float));
        let float = |tensor| publish(tensor, TensorKind::Float);
        AttentionGrads {
            offsets: float(grads.offsets),
            keys_values: float(grads.keys_values),
            encoder_weight: float(grads.encoder_weight),
            encoder_bias: float(grads.encoder_bias),
            queries: float(grads.queries),
            turned: float(grads.turned),
        }
    }
}
