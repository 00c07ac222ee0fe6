//! What the refiner's training reports: each step's record and each validation pass's scores, as the loop
//! returns them, `metrics.jsonl` holds them and a watcher ([`crate::watch`]) is shown them.

use serde::Serialize;

/// What one step did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepRecord {
    pub step: u64,
    pub loss: f64,
    pub l2: f64,
    pub lpips: f64,
    pub gram: f64,
    /// `None` for a step skipped before its update (a non-finite loss or gradient).
    pub grad_norm: Option<f64>,
    /// Why the step made no update (skipped or rolled back), when it did not.
    pub failure: Option<String>,
}

/// PSNR of the held-out pairs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Validation {
    pub step: u64,
    /// Mean PSNR (dB) of the refined renders against their targets.
    pub refined_psnr: f64,
    /// Mean PSNR (dB) of the renders as they are.
    pub render_psnr: f64,
}
