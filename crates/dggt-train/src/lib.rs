//! Training DGGT: the configuration, the per-sample objective (network, 4D scene assembly, rendering, weighted
//! losses), the optimiser (AdamW with groups, frozen modules, clipping, accumulation, warm-up and cosine
//! schedule), atomic checkpoints with exact resume, and validation.
//!
//! The loop is this crate's own rather than burn-train's learner: a step renders views assembled from a
//! forward pass with a host-side culling stage, skips non-finite steps without touching the weights, and
//! resumes bit-for-bit from `(weights, AdamW state, step)` because sampling and the schedule are pure functions
//! of the seed and the step. Those needs do not fit burn-train's supervised learner.

pub mod batch;
pub mod checkpoint;
pub mod config;
mod error;
pub mod objective;
pub mod optimizer;
pub mod schedule;
pub mod trainer;
pub mod validate;

pub use config::TrainConfig;
pub use error::TrainError;
pub use trainer::{RunOptions, RunSummary, Trainer, fresh_model, model_config};
