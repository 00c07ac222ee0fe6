//! The `[optim]` section of a run's configuration: AdamW, the learning-rate schedule, clipping, accumulation,
//! parameter groups and frozen modules. Groups and frozen modules are named by the trainer of the network
//! (the DGGT trainer names its top-level modules); a trainer without them leaves both empty.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// `optim.max_failed_steps_in_a_row` when not configured.
pub const DEFAULT_MAX_FAILED_STEPS_IN_A_ROW: u64 = 5;

/// AdamW, learning-rate schedule, clipping, accumulation, parameter groups and frozen modules.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimSection {
    /// Peak learning rate of every trainable parameter outside `groups`.
    pub lr: f64,
    /// Top-level modules (`sky_model`, `gs_head`, ...) with their own peak learning rate.
    pub groups: BTreeMap<String, f64>,
    /// Top-level modules that are not trained (the release freezes `aggregator`, `camera_head`, `depth_head`).
    pub frozen: Vec<String>,
    pub weight_decay: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
    /// Linear warm-up from 0 over this many steps, then cosine decay to `min_lr_ratio · lr`.
    pub warmup_steps: u64,
    pub min_lr_ratio: f64,
    /// Clip the global gradient norm to this value; `None` disables clipping.
    pub clip_grad_norm: Option<f64>,
    /// Samples whose gradients are summed (averaged) per optimiser step.
    pub accumulation: usize,
    /// The first steps train the camera loss alone (`loss.camera`, against the export's poses): the aggregator
    /// and camera head run, no dense head and no render, so each costs a fraction of a full step. For training
    /// from scratch, where the camera head otherwise learns per-frame positions last. Counted in `run.steps`
    /// and the schedule.
    pub pose_warmup_steps: u64,
    /// Steps in a row that may fail (skipped for a non-finite loss or gradient, or rolled back for an update
    /// that made a weight non-finite) before the run stops as diverged ([`crate::divergence`]).
    pub max_failed_steps_in_a_row: u64,
    /// A moving average of the trained weights, which validation scores and checkpoints give to inference
    /// ([`crate::average`]); none when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub average: Option<AverageSection>,
    /// Skips the update of a step whose loss jumps far above the recent ones ([`crate::spikes`]); none when
    /// absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skip_loss_spikes: Option<SpikeSection>,
}

/// `[optim.skip_loss_spikes]`: a step whose loss exceeds `factor` times the median of the last `window` steps'
/// losses makes no update.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpikeSection {
    /// How many times the recent median a loss must exceed to be a spike (above 1).
    pub factor: f64,
    /// Steps whose losses the median is taken over; no step is skipped before that many have run.
    pub window: usize,
}

/// `[optim.average]`: an exponential moving average of the trained weights from `start_step` on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AverageSection {
    /// The average's share kept at each step, in (0, 1): it spans about `1 / (1 - decay)` steps.
    pub decay: f64,
    /// Steps taken when the average starts, as a copy of the weights then.
    pub start_step: u64,
}

impl Default for OptimSection {
    fn default() -> Self {
        Self {
            lr: 4e-5,
            groups: [("sky_model".to_string(), 1e-4)].into_iter().collect(),
            frozen: Vec::new(),
            weight_decay: 1e-4,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            warmup_steps: 1000,
            min_lr_ratio: 0.0,
            clip_grad_norm: Some(1.0),
            accumulation: 1,
            pose_warmup_steps: 0,
            max_failed_steps_in_a_row: DEFAULT_MAX_FAILED_STEPS_IN_A_ROW,
            average: None,
            skip_loss_spikes: None,
        }
    }
}
