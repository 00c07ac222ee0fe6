//! Training DGGT: the configuration, the optimiser (AdamW with groups, frozen modules, clipping, accumulation,
//! warm-up and cosine schedule), atomic checkpoints with exact resume, and validation. A sample's objective
//! (network, 4D scene, weighted losses) is `dggt-objective`'s; the network, its checkpoints and its scenes are
//! reached through `dggt-infer`.
//!
//! The loop is this crate's own rather than burn-train's learner: a step renders views assembled from a
//! forward pass with a host-side culling stage, skips or rolls back non-finite steps (stopping a diverged run),
//! and resumes bit-for-bit from `(weights, AdamW state, step)` because sampling and the schedule are pure functions
//! of the seed and the step. Those needs do not fit burn-train's supervised learner.

pub mod checkpoint;
pub mod config;
pub mod divergence;
mod error;
pub mod failpoint;
pub mod finite;
pub mod optimizer;
pub mod replicas;
pub mod resume;
pub mod run_folder;
pub mod schedule;
pub mod trainer;
pub mod validate;

pub use config::TrainConfig;
/// Whether a training step reads the depth-and-flow maps ([`Trainer::train_step`] takes it).
pub use dggt_objective::DepthFlowMaps;
pub use error::TrainError;
pub use trainer::{RunOptions, RunSummary, Start, Trainer};
