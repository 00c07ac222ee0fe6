//! Training DGGT: the configuration, the network's modules (frozen ones, optimiser groups), its checkpoints with
//! exact resume, and validation. The run's machinery (AdamW, the schedule, checkpoint folders, divergence,
//! metric records) is `dggt-run`'s; a sample's objective (network, 4D scene, weighted losses) is
//! `dggt-objective`'s; the network, its checkpoints and its scenes are reached through `dggt-infer`.
//!
//! The loop is this crate's own rather than burn-train's learner: a step renders views assembled from a
//! forward pass with a host-side culling stage, skips or rolls back non-finite steps (stopping a diverged run),
//! and resumes bit-for-bit from `(weights, AdamW state, step)` because sampling and the schedule are pure functions
//! of the seed and the step. Those needs do not fit burn-train's supervised learner.

pub mod checkpoint;
pub mod config;
mod error;
pub mod modules;
pub mod rank_gradients;
pub mod ranks;
pub mod records;
pub mod replicas;
pub mod resume;
pub mod snapshot;
pub mod trainer;
pub mod validate;
pub mod watch;

pub use config::TrainConfig;
/// The processes a run trains in: this one alone, or the ranks of an MPI job.
pub use dggt_collective::ProcessGroup;
/// Whether a training step reads the depth-and-flow maps ([`Trainer::train_step`] takes it).
pub use dggt_objective::DepthFlowMaps;
/// How a run starts: fresh, or resuming the newest checkpoint of its folder.
pub use dggt_run::Start;
pub use error::TrainError;
pub use records::StepRecord;
pub use snapshot::{SnapshotOptions, ValidationSnapshot, ValidationViews};
pub use trainer::{RunOptions, RunSummary, Trainer};
pub use watch::RunWatcher;
