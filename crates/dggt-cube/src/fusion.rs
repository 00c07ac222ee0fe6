//! Ops whose kernels run eagerly on burn's fused CubeCL backend (`Fusion<CubeBackend>`, what a wgpu or CUDA device
//! dispatches to when burn's `fusion` feature is on). An op whose buffer sizes depend on its data, or that keeps
//! device buffers for its backward pass, cannot be recorded lazily into a fusion stream: it [`resolve`]s its
//! inputs (flushing the operations queued on them), runs its kernels on [`CubeBackend`], and [`publish`]es the
//! results as new tensors of the stream, the way fusion registers data created outside it.

use burn::backend::TensorMetadata;
use burn::backend::fusion::stream::StreamId;
use burn::backend::fusion::{FusionBackend, FusionTensor, NoOp, get_client};
use burn::backend::ir::{BackendIr, InitOperationIr, OperationIr, OperationOutput};
use burn_cubecl::CubeBackend;
use burn_cubecl::tensor::CubeTensor;

/// The fusion runtime of [`CubeBackend`].
pub type Runtime = <CubeBackend as FusionBackend>::FusionRuntime;

/// Which kind of burn tensor a computed device tensor becomes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TensorKind {
    Float,
    Int,
}

/// The device tensor behind a fused tensor, once every operation producing it has run.
pub fn resolve(tensor: FusionTensor<Runtime>, kind: TensorKind) -> CubeTensor {
    let client = tensor.client.clone();
    match kind {
        TensorKind::Float => client.resolve_tensor_float::<CubeBackend>(tensor),
        TensorKind::Int => client.resolve_tensor_int::<CubeBackend>(tensor),
    }
}

/// Registers a computed device tensor in the current fusion stream.
pub fn publish(tensor: CubeTensor, kind: TensorKind) -> FusionTensor<Runtime> {
    let client = get_client::<CubeBackend>(&tensor.device);
    let (shape, dtype) = (tensor.shape(), tensor.dtype);
    let handle = match kind {
        TensorKind::Float => CubeBackend::float_tensor_handle(tensor),
        TensorKind::Int => CubeBackend::int_tensor_handle(tensor),
    };
    let desc = InitOperationIr::create(shape, dtype, || client.register_tensor_handle(handle));
    client.register(StreamId::current(), OperationIr::Init(desc), NoOp::<CubeBackend>::new()).output()
}
