//! [`AttentionKernels`] for burn's CubeCL backend (wgpu, CUDA): the fused op's forward and backward as the
//! kernels of [`kernels`], one cube per query. The saved state is the call's inputs on the device (contiguous,
//! the rows as `i32`); the backward recomputes each query's encodings and weights from them, as the host does.
//!
//! Device memory of a call besides its inputs: the output `[N, heads, width + hidden + 3]`; in the backward the
//! gradients shaped like the inputs and the encoder's per-query rows `[N, 4 hidden]` (summed by a tensor
//! reduction). No `[N, k, hidden]` tensor exists at any time. The shared memory of a cube holds the query's
//! encodings and weights, `k hidden + 2 heads k` floats; head shapes beyond [`SHARED_FLOATS`] run the tensor
//! operations instead ([`fits`]).

mod kernels;

use burn::backend::ops::{FloatTensorOps, IntTensorOps};
use burn::backend::tensor::FloatTensor;
use burn::backend::{DType, Shape, TensorMetadata};
use burn::tensor::{IntDType, Slice};
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::ops::numeric::{empty_device_dtype, zeros_client};
use burn_cubecl::tensor::CubeTensor;
use dggt_cube::atomic::{FloatAtomics, NativeAdd, SwapAdd};

use super::{AttentionGrads, AttentionInputs, AttentionKernels};
use kernels::{InputsLaunch, Sizes, UNITS, attention_backward_kernel, attention_forward_kernel};

/// Floats of shared memory a cube may use: WebGPU's guaranteed 16 KiB of workgroup storage.
pub const SHARED_FLOATS: usize = 4096;

/// Whether a head of `neighbours`, `heads` and `hidden` channels fits a cube's shared memory.
pub fn fits(neighbours: usize, heads: usize, hidden: usize) -> bool {
    neighbours * hidden + 2 * heads * neighbours <= SHARED_FLOATS
}

/// One call's inputs on the device, contiguous, with its sizes: the forward's saved state.
#[derive(Clone)]
pub struct CubeCall {
    sizes: Sizes,
    offsets: CubeTensor,
    rows: CubeTensor,
    keys_values: CubeTensor,
    encoder_weight: CubeTensor,
    encoder_bias: CubeTensor,
    queries: CubeTensor,
    turned: CubeTensor,
}

impl std::fmt::Debug for CubeCall {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CubeCall").field("sizes", &self.sizes).field("queries", &self.queries_count()).finish()
    }
}

fn float_input(tensor: CubeTensor, what: &str) -> CubeTensor {
    assert_eq!(tensor.dtype, DType::F32, "neighbour attention: `{what}` must be an f32 tensor, got {:?}", tensor.dtype);
    into_contiguous(tensor)
}

fn dims3(tensor: &CubeTensor) -> [usize; 3] {
    let shape = tensor.shape();
    [shape[0], shape[1], shape[2]]
}

impl CubeCall {
    fn new(inputs: AttentionInputs<CubeBackend>) -> Self {
        let [_, neighbours, _] = dims3(&inputs.offsets);
        let [_, heads, width] = dims3(&inputs.queries);
        let [_, _, hidden] = dims3(&inputs.turned);
        let rows = match inputs.rows.dtype {
            DType::I32 => inputs.rows,
            _ => CubeBackend::int_cast(inputs.rows, IntDType::I32),
        };
        Self {
            sizes: Sizes { neighbours, heads, width, hidden },
            offsets: float_input(inputs.offsets, "offsets"),
            rows: into_contiguous(rows),
            keys_values: float_input(inputs.keys_values, "keys_values"),
            encoder_weight: float_input(inputs.encoder_weight, "encoder_weight"),
            encoder_bias: float_input(inputs.encoder_bias, "encoder_bias"),
            queries: float_input(inputs.queries, "queries"),
            turned: float_input(inputs.turned, "turned"),
        }
    }

    /// Queries (`N`).
    fn queries_count(&self) -> usize {
        self.offsets.shape()[0]
    }

    fn client(&self) -> burn_cubecl::cubecl::client::Client {
        self.offsets.client.clone()
    }

    fn empty(&self, shape: Shape) -> CubeTensor {
        empty_device_dtype(self.client(), self.offsets.device.clone(), shape, DType::F32)
    }

    fn zeros(&self, shape: Shape) -> CubeTensor {
        zeros_client(self.client(), self.offsets.device.clone(), shape, DType::F32)
    }

    /// The inputs as the kernels' argument.
    fn kernel_inputs(&self) -> InputsLaunch {
        InputsLaunch::new(
            arg(&self.offsets),
            arg(&self.rows),
            arg(&self.keys_values),
            arg(&self.encoder_weight),
            arg(&self.encoder_bias),
            arg(&self.queries),
            arg(&self.turned),
        )
    }

    /// One cube per query, in rows of at most 65 535 cubes.
    fn launch_size(&self) -> (CubeCount, CubeDim) {
        let per_row = self.queries_count().clamp(1, 65_535);
        let rows = self.queries_count().div_ceil(per_row).max(1);
        (CubeCount::new_2d(per_row as u32, rows as u32), CubeDim::new_1d(UNITS as u32))
    }

    fn forward(&self) -> CubeTensor {
        let Sizes { heads, width, hidden, .. } = self.sizes;
        let out = self.empty(Shape::new([self.queries_count(), heads, width + hidden + 3]));
        if self.queries_count() == 0 {
            return out;
        }
        let (cubes, dim) = self.launch_size();
        attention_forward_kernel::launch(
            &self.client(),
            cubes,
            dim,
            self.kernel_inputs(),
            arg(&out),
            self.queries_count() as u32,
            self.sizes,
        );
        out
    }

    fn backward(&self, grad_out: CubeTensor) -> AttentionGrads<CubeBackend> {
        let Sizes { neighbours, heads, width, hidden } = self.sizes;
        let n = self.queries_count();
        let grads = AttentionGrads {
            offsets: self.empty(Shape::new([n, neighbours, 3])),
            keys_values: self.zeros(Shape::new([self.keys_values.shape()[0], 2 * heads * width])),
            encoder_weight: self.zeros(Shape::new([3, hidden])),
            encoder_bias: self.zeros(Shape::new([hidden])),
            queries: self.empty(Shape::new([n, heads, width])),
            turned: self.empty(Shape::new([n, heads, hidden])),
        };
        if n == 0 {
            return grads;
        }
        let encoder_rows = self.empty(Shape::new([n, 4 * hidden]));
        let grad_out = float_input(grad_out, "the output's gradient");
        let (cubes, dim) = self.launch_size();
        let launch = match FloatAtomics::of(&self.client()) {
            FloatAtomics::Native => attention_backward_kernel::launch::<NativeAdd>,
            FloatAtomics::CompareAndSwap => attention_backward_kernel::launch::<SwapAdd>,
        };
        launch(
            &self.client(),
            cubes,
            dim,
            self.kernel_inputs(),
            arg(&grad_out),
            arg(&grads.offsets),
            arg(&grads.queries),
            arg(&grads.turned),
            arg(&encoder_rows),
            arg(&grads.keys_values),
            n as u32,
            self.sizes,
        );
        let (encoder_weight, encoder_bias) = encoder_grads(encoder_rows, hidden);
        AttentionGrads { encoder_weight, encoder_bias, ..grads }
    }
}

/// The encoder's weight `[3, hidden]` and bias `[hidden]` gradients: the per-query rows `[N, 4 hidden]` summed.
fn encoder_grads(rows: CubeTensor, hidden: usize) -> (CubeTensor, CubeTensor) {
    let summed = CubeBackend::float_reshape(CubeBackend::float_sum_dim(rows, 0), Shape::new([4, hidden]));
    let weight = CubeBackend::float_slice(summed.clone(), &[Slice::from(0..3), Slice::from(0..hidden)]);
    let bias = CubeBackend::float_slice(summed, &[Slice::from(3..4), Slice::from(0..hidden)]);
    (into_contiguous(weight), into_contiguous(CubeBackend::float_reshape(bias, Shape::new([hidden]))))
}

fn arg(tensor: &CubeTensor) -> TensorArg {
    tensor.clone().into_tensor_arg()
}

impl AttentionKernels for CubeBackend {
    type Saved = CubeCall;

    fn attention_forward(inputs: AttentionInputs<Self>) -> (FloatTensor<Self>, Self::Saved) {
        let call = CubeCall::new(inputs);
        (call.forward(), call)
    }

    fn attention_backward(saved: Self::Saved, grad_out: FloatTensor<Self>) -> AttentionGrads<Self> {
        saved.backward(grad_out)
    }
}
