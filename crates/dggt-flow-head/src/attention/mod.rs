//! The core of the head's attention: each query's weighted sums over its `k` neighbours (values, hidden offset
//! encodings, offsets), given its per-head query and turned query (see [`crate::head`] for the factoring). Two
//! implementations of one contract:
//!
//! - **fused** ([`NeighbourAttentionOps`]): a burn backend extension that writes only the
//!   `[N, heads, width + hidden + 3]` output, with a hand-written backward that recomputes each query's encodings
//!   and weights instead of keeping `[N, k, hidden]` tensors. On `flex` it runs [`kernel`] per query in parallel
//!   and adds the shared gradients (target keys and values, the encoder) in one buffer per worker; on the CubeCL
//!   devices (features `wgpu` / `cuda`, and `fusion`) it runs `cube`'s kernels, one cube per query, adding the
//!   target keys' and values' gradients atomically.
//! - **tensor ops** ([`tensor_ops`], every other case: `ndarray`, `f64`, a head too wide for a cube's shared
//!   memory): the neighbours' keys and values gathered and the same sums taken with burn's operations and
//!   autodiff.
//!
//! `tests/flow_head/attention.rs` holds both against the documented formulas, and the device kernels against the host's;
//! `tests/flow_head/gradients.rs` checks the fused backward against finite differences.

mod autodiff;
#[cfg(any(feature = "wgpu", feature = "cuda"))]
mod cube;
#[cfg(all(any(feature = "wgpu", feature = "cuda"), feature = "fusion"))]
mod fusion;
pub mod gelu;
mod host;
pub mod kernel;
mod tensor_ops;

use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Backend, DispatchDevice, ExtensionType, backend_extension};
use burn::tensor::{DType, Int, Tensor};

/// The attention's inputs for one chunk of `N` queries (shapes as in [`kernel`]'s table).
#[derive(Debug, Clone)]
pub struct AttentionTensors {
    /// `[N, k, 3]`.
    pub offsets: Tensor<3>,
    /// `[N, k]`: rows of `keys_values`.
    pub rows: Tensor<2, Int>,
    /// `[Nt, 2 hidden]`.
    pub keys_values: Tensor<2>,
    /// `[3, hidden]` and `[hidden]`: the offset encoding's first layer.
    pub encoder_weight: Tensor<2>,
    pub encoder_bias: Tensor<1>,
    /// `[N, heads, width]`, divided by `sqrt(width)`.
    pub queries: Tensor<3>,
    /// `[N, heads, hidden]`, divided by `sqrt(width)`.
    pub turned: Tensor<3>,
}

/// What every head collects from its neighbourhood.
#[derive(Debug, Clone)]
pub struct AttendedTensors {
    /// `[N, heads, width]`: the weighted values of the neighbours' features.
    pub values: Tensor<3>,
    /// `[N, heads, hidden]`: the weighted hidden encodings of the neighbours' offsets.
    pub pooled: Tensor<3>,
    /// `[N, heads, 3]`: the weighted offsets.
    pub matched: Tensor<3>,
}

/// Which implementation runs on a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AttentionKernel {
    Fused,
    TensorOps,
}

impl AttentionKernel {
    /// The fused op for `f32` queries `[N, hidden]` on `flex`, and on a CubeCL device where the head's shape fits
    /// a cube's shared memory (under autodiff or not); tensor operations otherwise.
    pub fn for_queries(queries: &Tensor<2>, neighbours: usize, heads: usize) -> Self {
        if queries.dtype() != DType::F32 {
            return Self::TensorOps;
        }
        match queries.device().without_autodiff().as_dispatch() {
            DispatchDevice::Flex(_) => Self::Fused,
            #[cfg(any(feature = "wgpu", feature = "cuda"))]
            DispatchDevice::Cube(_) if cube::fits(neighbours, heads, queries.dims()[1]) => Self::Fused,
            _ => {
                let _ = (neighbours, heads);
                Self::TensorOps
            }
        }
    }
}

/// The attention's sums with `kernel`.
pub fn attend(inputs: AttentionTensors, kernel: AttentionKernel) -> AttendedTensors {
    match kernel {
        AttentionKernel::Fused => fused(inputs),
        AttentionKernel::TensorOps => tensor_ops::attend(inputs),
    }
}

fn fused(inputs: AttentionTensors) -> AttendedTensors {
    let [_, _, width] = inputs.queries.dims();
    let [_, _, hidden] = inputs.turned.dims();
    let packed = AttentionInputs {
        offsets: inputs.offsets.into_dispatch(),
        rows: inputs.rows.into_dispatch(),
        keys_values: inputs.keys_values.into_dispatch(),
        encoder_weight: inputs.encoder_weight.into_dispatch(),
        encoder_bias: inputs.encoder_bias.into_dispatch(),
        queries: inputs.queries.into_dispatch(),
        turned: inputs.turned.into_dispatch(),
    };
    let out =
        Tensor::<3>::from_dispatch(<burn::backend::Dispatch as NeighbourAttentionOps>::neighbour_attention(packed));
    AttendedTensors {
        values: out.clone().narrow(2, 0, width),
        pooled: out.clone().narrow(2, width, hidden),
        matched: out.narrow(2, width + hidden, 3),
    }
}

/// The fused attention as a burn backend extension (`flex`, the CubeCL devices, and autodiff over them). Returns
/// the packed `[N, heads, width + hidden + 3]` output; gradients reach every float input.
#[backend_extension(
    Flex,
    // burn's `Cube` type: `CubeBackend`, or `Fusion<CubeBackend>` when burn's `fusion` feature is on.
    Cube: cfg(any(feature = "wgpu", feature = "cuda")),
    Autodiff
)]
pub trait NeighbourAttentionOps: Backend {
    fn neighbour_attention(#[extension_type] inputs: AttentionInputs<Self>) -> FloatTensor<Self>;
}

/// [`AttentionTensors`] as backend primitives.
#[derive(Debug, Clone, ExtensionType)]
pub struct AttentionInputs<B: Backend> {
    pub offsets: FloatTensor<B>,
    pub rows: IntTensor<B>,
    pub keys_values: FloatTensor<B>,
    pub encoder_weight: FloatTensor<B>,
    pub encoder_bias: FloatTensor<B>,
    pub queries: FloatTensor<B>,
    pub turned: FloatTensor<B>,
}

/// Gradients of the float inputs, shaped like them.
#[derive(Debug, Clone)]
pub struct AttentionGrads<B: Backend> {
    pub offsets: FloatTensor<B>,
    pub keys_values: FloatTensor<B>,
    pub encoder_weight: FloatTensor<B>,
    pub encoder_bias: FloatTensor<B>,
    pub queries: FloatTensor<B>,
    pub turned: FloatTensor<B>,
}

/// A backend's fused attention: forward with the state its backward needs, and that backward.
pub trait AttentionKernels: Backend {
    type Saved: Clone + Send + Sync + core::fmt::Debug + 'static;

    fn attention_forward(inputs: AttentionInputs<Self>) -> (FloatTensor<Self>, Self::Saved);

    fn attention_backward(saved: Self::Saved, grad_out: FloatTensor<Self>) -> AttentionGrads<Self>;
}

impl<B: AttentionKernels> NeighbourAttentionOps for B {
    fn neighbour_attention(inputs: AttentionInputs<Self>) -> FloatTensor<Self> {
        B::attention_forward(inputs).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;

    #[test]
    fn the_fused_op_runs_for_f32_on_flex_with_or_without_autodiff() {
        let kernel = |device: &Device, dtype: DType| {
            AttentionKernel::for_queries(&Tensor::<2>::zeros([2, 4], (device, dtype)), 16, 2)
        };
        let flex = Device::flex();
        assert_eq!(kernel(&flex, DType::F32), AttentionKernel::Fused);
        assert_eq!(kernel(&flex.clone().autodiff(), DType::F32), AttentionKernel::Fused);
        assert_eq!(kernel(&flex, DType::F64), AttentionKernel::TensorOps);
    }
}
