//! A training run, whatever it trains: the optimiser (AdamW with groups, clipping and a rollback of updates that leave
//! non-finite values), the learning-rate schedule, a moving average of the weights, skipping loss spikes, tensor work
//! run on one of rayon's threads (`compute_pool`), what a viewer is shown (`[viewer]`), checkpoint folders with their
//! run state and the `latest` pointer, the rules of a run's output folder and of resuming in it, divergence (steps that
//! make no update, and when to give up), the progress bar and the metric records of `metrics.jsonl`.
//!
//! The DGGT trainer (`dggt-train`) and the refiner's trainer (`dggt-refine-train`) share all of it; what is
//! particular to a network (its modules, its configuration, its samples) stays with its trainer.

pub mod average;
pub mod checkpoint;
pub mod compute_pool;
pub mod divergence;
mod error;
pub mod failpoint;
pub mod finite;
mod host_adamw;
pub mod metrics;
pub mod optim_config;
pub mod optimizer;
pub mod progress;
pub mod run_folder;
pub mod schedule;
pub mod spikes;
pub mod viewer;

pub use error::RunError;
pub use optim_config::OptimSection;
pub use optimizer::Optimizer;
pub use run_folder::Start;
pub use viewer::ViewerSection;
