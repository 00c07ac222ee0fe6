//! GPU gradients summed across ranks on the device, by NCCL, for ranks whose gradients live on a CUDA device.
//!
//! The communicator is bootstrapped over the MPI group: rank 0 asks NCCL for a unique id, MPI broadcasts its 128
//! bytes, and every rank joins with its rank and the group's size, one CUDA device per rank (the device that
//! holds the rank's summed gradients; a rank's other devices are summed onto it first). NCCL is loaded at run time
//! (`libnccl.so.2`), so a build with this module needs neither NCCL nor a GPU, and a machine without NCCL gets an
//! error at start-up rather than at the first step.
//!
//! A sum reads the input tensor's device buffer and writes a new buffer, never the input in place: gradient
//! buffers can be shared between parameters (autodiff hands the same gradient to both operands of an addition).
//! The order of work is explicit: every kernel queued on the device has finished before NCCL reads (a device
//! sync), and the sum has landed before the tensor is handed back (a sync of the communicator's own stream), so
//! no CUDA event has to be shared with CubeCL's streams. Overlapping the sums with the backward pass is planned
//! in `docs/DISTRIBUTED.md`.

use std::ffi::c_void;
use std::mem::MaybeUninit;
use std::sync::Mutex;

use burn::backend::Cube;
use burn::tensor::{DType, Device, Tensor};
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl::cuda::CudaRuntime;
use burn_cubecl::cubecl::future::block_on;
use burn_cubecl::tensor::CubeTensor;
use cubecl_runtime::runtime::Runtime;
use cudarc::driver::result as cuda;
use cudarc::driver::sys::CUstream;
use cudarc::nccl::result as nccl;
use cudarc::nccl::sys::{ncclComm_t, ncclDataType_t, ncclRedOp_t, ncclUniqueId};

use crate::error::CollectiveError;
use crate::group::ProcessGroup;

/// The server behind a CUDA client, whose storage hands out raw device pointers.
type CudaServer = <CudaRuntime as Runtime>::Server;

/// This rank's member of an NCCL communicator spanning the process group, on one CUDA device.
pub struct NcclCommunicator {
    /// Locked for every call, so that calls from several threads never overlap.
    handles: Mutex<Handles>,
    device_index: usize,
}

/// The communicator and the stream its sums run on.
struct Handles {
    comm: ncclComm_t,
    stream: CUstream,
}

// SAFETY: an NCCL communicator and a CUDA stream may be used from any thread as long as calls on them do not
// overlap, which the mutex around them ensures.
unsafe impl Send for Handles {}

impl std::fmt::Debug for NcclCommunicator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NcclCommunicator(cuda:{})", self.device_index)
    }
}

impl NcclCommunicator {
    /// Joins every rank of `group` into one communicator, this rank on `device` (a CUDA device). Every rank calls
    /// it at the same point.
    pub fn join(group: &ProcessGroup, device: &Device) -> Result<Self, CollectiveError> {
        let device_index = cuda_index(device)?;
        if !library_present() {
            return Err(CollectiveError::NcclMissing);
        }
        make_current(device_index)?;
        let id = shared_unique_id(group)?;
        let mut comm = MaybeUninit::uninit();
        // SAFETY: `comm` is written by a successful call, which is what makes `assume_init` valid; every rank
        // passes the same id and size and its own rank.
        let comm = unsafe {
            nccl::comm_init_rank(comm.as_mut_ptr(), group.size() as i32, id, group.rank() as i32)
                .map_err(|error| nccl_error("joining the communicator", &error))?;
            comm.assume_init()
        };
        let stream = cuda::stream::create(cuda::stream::StreamKind::NonBlocking)
            .map_err(|error| cuda_error("creating the communicator's stream", error))?;
        Ok(Self { handles: Mutex::new(Handles { comm, stream }), device_index })
    }

    /// The element-wise sum of `values` over every rank, a new tensor on the same device. Every rank calls it
    /// with a tensor of the same length, in the same order of calls.
    // The handle clones keep `source` and `summed` owning their buffers while NCCL uses the raw pointers.
    #[allow(clippy::redundant_clone)]
    pub fn all_reduce_sum(&self, values: Tensor<1>) -> Result<Tensor<1>, CollectiveError> {
        let count = values.dims()[0];
        let target = Tensor::<1>::zeros([count], &values.device());
        let source = device_tensor(values)?;
        let summed = device_tensor(target.clone())?;
        if source.dtype != DType::F32 || !source.is_contiguous() {
            return Err(CollectiveError::DeviceLayout { dtype: format!("{:?}", source.dtype) });
        }
        let client = source.client.clone();
        block_on(client.sync()).map_err(|error| device_error("finishing the kernels before the sum", error))?;
        let read = client
            .get_resource::<CudaServer>(source.handle.clone())
            .map_err(|error| device_error("finding the gradients' device buffer", error))?;
        let write = client
            .get_resource::<CudaServer>(summed.handle.clone())
            .map_err(|error| device_error("finding the sum's device buffer", error))?;
        let handles = self.handles.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        make_current(self.device_index)?;
        // SAFETY: both pointers are live device allocations of `count` f32 values on this communicator's device
        // (the managed resources keep them in place until they are dropped below); the communicator was
        // joined by `join`.
        unsafe {
            nccl::all_reduce(
                read.resource().ptr as *const c_void,
                write.resource().ptr as *mut c_void,
                count,
                ncclDataType_t::ncclFloat32,
                ncclRedOp_t::ncclSum,
                handles.comm,
                handles.stream as _,
            )
            .map_err(|error| nccl_error("summing the gradients", &error))?;
            cuda::stream::synchronize(handles.stream).map_err(|error| cuda_error("waiting for the sum", error))?;
        }
        drop((read, write, handles));
        Ok(target)
    }
}

impl Drop for Handles {
    fn drop(&mut self) {
        // SAFETY: both were created by `NcclCommunicator::join` and are not used after this.
        unsafe {
            if let Err(error) = nccl::comm_destroy(self.comm) {
                tracing::warn!("NCCL communicator not released: {error:?}");
            }
            if let Err(error) = cuda::stream::destroy(self.stream) {
                tracing::warn!("CUDA stream of the NCCL communicator not released: {error:?}");
            }
        }
    }
}

/// Whether `device` is a CUDA device (whose tensors NCCL can sum).
pub fn is_cuda(device: &Device) -> bool {
    cuda_index(device).is_ok()
}

/// Whether this machine has the NCCL library ([`NcclCommunicator::join`] fails without it).
pub fn library_present() -> bool {
    // SAFETY: only probes whether the shared library can be opened.
    unsafe { cudarc::nccl::sys::is_culib_present() }
}

/// The CUDA device number behind a burn device, or an error naming the device when it is not a CUDA one.
fn cuda_index(device: &Device) -> Result<usize, CollectiveError> {
    let inner = device.clone().inner();
    match inner.as_dispatch() {
        burn::backend::DispatchDevice::Cube(CubeDevice::Cuda(cuda)) => Ok(cuda.index),
        #[allow(unreachable_patterns)]
        _ => Err(CollectiveError::NotCuda { device: format!("{inner:?}") }),
    }
}

/// Makes the primary context of CUDA device `index` (the one CubeCL's CUDA runtime uses) current on this thread.
fn make_current(index: usize) -> Result<(), CollectiveError> {
    let device = cuda::device::get(index as i32).map_err(|error| cuda_error("finding the device", error))?;
    // SAFETY: `device` is a valid device handle; retaining its primary context returns the context CubeCL
    // created its buffers in (retaining is reference-counted, so it is not a new context).
    unsafe {
        let context = cuda::primary_ctx::retain(device).map_err(|error| cuda_error("retaining the context", error))?;
        cuda::ctx::set_current(context).map_err(|error| cuda_error("making the context current", error))
    }
}

/// Rank 0's NCCL unique id, on every rank.
fn shared_unique_id(group: &ProcessGroup) -> Result<ncclUniqueId, CollectiveError> {
    let mut bytes = [0u8; 128];
    if group.is_writer() {
        let id = nccl::get_uniqueid().map_err(|error| nccl_error("creating the communicator's id", &error))?;
        for (byte, value) in bytes.iter_mut().zip(id.internal) {
            *byte = value as u8;
        }
    }
    group.broadcast_bytes(&mut bytes);
    Ok(ncclUniqueId { internal: bytes.map(|byte| byte as std::ffi::c_char) })
}

/// The CubeCL tensor behind a float tensor on a CubeCL device, once the operations producing it have run.
fn device_tensor(values: Tensor<1>) -> Result<CubeTensor, CollectiveError> {
    let primitive = values
        .try_into_primitive::<Cube>()
        .map_err(|error| CollectiveError::DeviceLayout { dtype: format!("not a CubeCL tensor ({error:?})") })?;
    #[cfg(feature = "fusion")]
    let primitive = {
        let client = primitive.client.clone();
        client.resolve_tensor_float::<burn_cubecl::CubeBackend>(primitive)
    };
    Ok(primitive)
}

fn nccl_error(doing: &'static str, error: &nccl::NcclError) -> CollectiveError {
    CollectiveError::Nccl { doing, code: format!("{error:?}") }
}

fn cuda_error(doing: &'static str, error: cuda::DriverError) -> CollectiveError {
    CollectiveError::Nccl { doing, code: format!("CUDA {error:?}") }
}

fn device_error(doing: &'static str, error: impl std::fmt::Debug) -> CollectiveError {
    CollectiveError::Nccl { doing, code: format!("{error:?}") }
}
