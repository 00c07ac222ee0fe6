//! Errors of the process group; each says what was expected.

use crate::rank::Rank;

/// What went wrong in a collective operation or in setting the group up.
#[derive(Debug, thiserror::Error)]
pub enum CollectiveError {
    /// The program was started under an MPI launcher but this build has no MPI support.
    #[error(
        "started as rank {rank} of {size} by an MPI launcher, but this build has no MPI support (build with the `mpi` feature)"
    )]
    NoMpiSupport { rank: String, size: String },
    /// MPI could not be initialised (it already was, or the launcher's environment is broken).
    #[error("MPI could not be initialised: {0}")]
    Init(&'static str),
    /// The ranks disagree on the size of a buffer they sum: they would exchange garbage.
    #[error(
        "rank {rank} sums {local} values, and the ranks' lengths range from {smallest} to {largest}: the ranks hold \
         different models"
    )]
    SizeMismatch { rank: Rank, local: usize, smallest: usize, largest: usize },
    /// A bucket size of zero elements cannot make progress.
    #[error("bucket size must be at least one element")]
    EmptyBucket,
    /// NCCL sums CUDA tensors, and this rank's gradients live elsewhere.
    #[error("NCCL sums gradients on CUDA devices, and this rank's live on {device}")]
    NotCuda { device: String },
    /// The build sums through NCCL, and the machine has no NCCL library.
    #[error(
        "NCCL (libnccl.so.2) was not found on this machine: install it (NVIDIA's `libnccl2` package) or put it on \
         LD_LIBRARY_PATH"
    )]
    NcclMissing,
    /// NCCL sums contiguous `f32` device buffers.
    #[error("NCCL sums contiguous f32 device buffers; this one is {dtype}")]
    DeviceLayout { dtype: String },
    /// NCCL, the CUDA driver or the device's runtime failed.
    #[error("NCCL on the device failed while {doing}: {code}")]
    Nccl { doing: &'static str, code: String },
}
