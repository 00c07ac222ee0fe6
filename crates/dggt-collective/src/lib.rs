//! Training across processes: every process (an MPI rank) holds a replica of the network, computes gradients
//! on its own samples, and the gradients are summed over all ranks before the same step is taken everywhere.
//!
//! - [`group`]: the process group: one process alone, or the ranks of an MPI job (`mpirun -np P`, `srun`), with
//!   the feature `mpi`;
//! - [`bucket`]: the all-reduce of a model's gradients in buckets of bounded size, so that the host copy never
//!   holds a second full set of gradients;
//! - `nccl` (feature `nccl`): the sum of CUDA gradients on the device by NCCL, bootstrapped over the MPI group.
//!
//! Without NCCL the sums are of host `f32` buffers: GPU gradients are copied to the host bucket by bucket. Within
//! one process, replicas on several devices are summed by the trainer first; the group then sums across processes.

pub mod bucket;
mod error;
pub mod group;
#[cfg(feature = "nccl")]
pub mod nccl;
mod rank;

pub use bucket::{BucketPlan, all_reduce_bucketed};
pub use error::CollectiveError;
pub use group::ProcessGroup;
pub use rank::Rank;
