//! The process group a training run belongs to: this process alone, or one rank of an MPI job.
//!
//! Which one is decided at start-up from the environment: a process started by `mpirun` (Open MPI, MPICH) or
//! `srun` (Slurm) sees its launcher's rank variables and joins the MPI world; one started plainly is a group of
//! one. A build without the `mpi` feature refuses to run as one rank of several (each would train alone and
//! write the same files) rather than silently ignoring its siblings.

use crate::error::CollectiveError;
use crate::rank::Rank;

/// The environment variables by which launchers tell a process its rank and the job's size: Open MPI's
/// `mpirun`, MPICH's (and Slurm's PMI), and a Slurm job step started by `srun`. Slurm's job-wide
/// `SLURM_NTASKS` is not one of them: a batch script sees it too, and a `dggt` started there without `srun` is
/// one process, not rank 0 of the tasks the job asked for.
const LAUNCHER_VARIABLES: [(&str, &str); 3] = [
    ("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"),
    ("PMI_RANK", "PMI_SIZE"),
    ("SLURM_PROCID", "SLURM_STEP_NUM_TASKS"),
];

/// The group of processes that train together.
pub enum ProcessGroup {
    /// This process alone: sums are the identity.
    Single,
    /// One rank of an MPI job.
    #[cfg(feature = "mpi")]
    Mpi(crate::group::mpi_group::MpiGroup),
}

impl std::fmt::Debug for ProcessGroup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ProcessGroup(rank {} of {})", self.rank(), self.size())
    }
}

impl ProcessGroup {
    /// The group this process was started in: the MPI world when a launcher started it as one of several
    /// ranks, else this process alone.
    pub fn from_environment() -> Result<Self, CollectiveError> {
        match launched_rank(|name| std::env::var(name).ok()) {
            Some((rank, size)) if size != "1" => Self::join_mpi(rank, size),
            _ => Ok(Self::Single),
        }
    }

    #[cfg(feature = "mpi")]
    fn join_mpi(_rank: String, _size: String) -> Result<Self, CollectiveError> {
        Ok(Self::Mpi(mpi_group::MpiGroup::initialise()?))
    }

    #[cfg(not(feature = "mpi"))]
    fn join_mpi(rank: String, size: String) -> Result<Self, CollectiveError> {
        Err(CollectiveError::NoMpiSupport { rank, size })
    }

    /// This process's rank.
    pub fn rank(&self) -> Rank {
        match self {
            Self::Single => 0,
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.rank(),
        }
    }

    /// How many ranks train together.
    pub fn size(&self) -> usize {
        match self {
            Self::Single => 1,
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.size(),
        }
    }

    /// Whether this rank writes the run's files (checkpoints, metrics, validation): rank 0 alone.
    pub fn is_writer(&self) -> bool {
        self.rank() == 0
    }

    /// Replaces `values` on every rank by their element-wise sum over all ranks. Every rank must call it with
    /// a buffer of the same length, in the same order of calls.
    // Without MPI the only group is a single process, whose sum leaves `values` as they are.
    #[cfg_attr(not(feature = "mpi"), allow(unused_variables))]
    pub fn all_reduce_sum(&self, values: &mut [f32]) -> Result<(), CollectiveError> {
        match self {
            Self::Single => Ok(()),
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.all_reduce_sum(values),
        }
    }

    /// [`ProcessGroup::all_reduce_sum`] of `f64` values (losses and counts summed for the log).
    #[cfg_attr(not(feature = "mpi"), allow(unused_variables))]
    pub fn all_reduce_sum_f64(&self, values: &mut [f64]) -> Result<(), CollectiveError> {
        match self {
            Self::Single => Ok(()),
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.all_reduce_sum(values),
        }
    }

    /// Rank 0's `value` on every rank (a seed, a step to resume from).
    pub fn broadcast_u64(&self, value: u64) -> u64 {
        match self {
            Self::Single => value,
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.broadcast_u64(value),
        }
    }

    /// Overwrites `bytes` on every rank with rank 0's (an identifier another library's group is set up with).
    /// Every rank passes a buffer of the same length.
    #[cfg_attr(not(feature = "mpi"), allow(unused_variables))]
    pub fn broadcast_bytes(&self, bytes: &mut [u8]) {
        match self {
            Self::Single => {}
            #[cfg(feature = "mpi")]
            Self::Mpi(group) => group.broadcast_bytes(bytes),
        }
    }
}

// The trainer's device threads share the group (only the thread that created it calls collectives).
const _: () = {
    const fn shared_between_threads<T: Send + Sync>() {}
    shared_between_threads::<ProcessGroup>();
};

/// The rank and size a launcher gave this process, as their text, `variable` reading the environment.
fn launched_rank(variable: impl Fn(&str) -> Option<String>) -> Option<(String, String)> {
    LAUNCHER_VARIABLES.iter().find_map(|(rank, size)| Some((variable(rank)?, variable(size)?)))
}

#[cfg(test)]
mod tests {
    use super::launched_rank;

    fn environment(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        move |name| pairs.iter().find(|(key, _)| key == name).map(|(_, value)| value.clone())
    }

    #[test]
    fn mpirun_and_srun_name_the_rank_and_size() {
        let open_mpi = environment(&[("OMPI_COMM_WORLD_RANK", "1"), ("OMPI_COMM_WORLD_SIZE", "4")]);
        assert_eq!(launched_rank(open_mpi), Some(("1".into(), "4".into())));
        let srun = environment(&[("SLURM_PROCID", "2"), ("SLURM_STEP_NUM_TASKS", "8"), ("SLURM_NTASKS", "8")]);
        assert_eq!(launched_rank(srun), Some(("2".into(), "8".into())));
    }

    #[test]
    fn a_slurm_batch_script_without_srun_is_one_process() {
        let batch = environment(&[("SLURM_PROCID", "0"), ("SLURM_NTASKS", "8"), ("SLURM_JOB_ID", "77")]);
        assert_eq!(launched_rank(batch), None);
    }
}

#[cfg(feature = "mpi")]
pub(crate) mod mpi_group {
    //! One rank of an MPI job, over rsmpi. Only the MPI environment is held (the world communicator is taken
    //! per call), so the group can sit in a trainer whose worker threads share it; MPI is initialised as
    //! "funneled": every collective is called from the thread that initialised it.

    use mpi::collective::SystemOperation;
    use mpi::datatype::Equivalence;
    use mpi::environment::Universe;
    use mpi::topology::SimpleCommunicator;
    use mpi::traits::{Communicator, CommunicatorCollectives, Root};

    use crate::error::CollectiveError;
    use crate::rank::Rank;

    /// The MPI world of this job; MPI is finalised when it is dropped.
    pub struct MpiGroup {
        rank: Rank,
        size: usize,
        _universe: Universe,
    }

    impl MpiGroup {
        pub(crate) fn initialise() -> Result<Self, CollectiveError> {
            let (universe, _) = mpi::initialize_with_threading(mpi::Threading::Funneled)
                .ok_or(CollectiveError::Init("it was initialised before"))?;
            let world = universe.world();
            Ok(Self { rank: world.rank() as Rank, size: world.size() as usize, _universe: universe })
        }

        fn world(&self) -> SimpleCommunicator {
            SimpleCommunicator::world()
        }

        pub(crate) fn rank(&self) -> Rank {
            self.rank
        }

        pub(crate) fn size(&self) -> usize {
            self.size
        }

        /// Every rank first learns the smallest and largest length summed (one small all-reduce), so that a
        /// mismatch fails on every rank instead of leaving some waiting on the others.
        pub(crate) fn all_reduce_sum<T: Equivalence + Copy>(&self, values: &mut [T]) -> Result<(), CollectiveError> {
            let world = self.world();
            let local = values.len() as i64;
            let mut extremes = [0i64; 2];
            world.all_reduce_into(&[local, -local][..], &mut extremes[..], SystemOperation::max());
            let (largest, smallest) = (extremes[0], -extremes[1]);
            if largest != smallest {
                return Err(CollectiveError::SizeMismatch {
                    rank: self.rank(),
                    local: values.len(),
                    smallest: smallest as usize,
                    largest: largest as usize,
                });
            }
            let send = values.to_vec();
            world.all_reduce_into(&send[..], values, SystemOperation::sum());
            Ok(())
        }

        pub(crate) fn broadcast_u64(&self, value: u64) -> u64 {
            let mut value = value;
            self.world().process_at_rank(0).broadcast_into(&mut value);
            value
        }

        pub(crate) fn broadcast_bytes(&self, bytes: &mut [u8]) {
            self.world().process_at_rank(0).broadcast_into(bytes);
        }
    }
}
