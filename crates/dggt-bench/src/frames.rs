//! Which of a scene's frames are targets (rendered and compared with the export's images) and which feed the
//! network. Targets are never inputs, so the ground-truth error measures novel-time renders; inputs are spread
//! evenly over the remaining frames with the first and last always included, so every target lies inside the
//! inputs' time span (the cameras are interpolated, never extrapolated).
//!
//! Frames are positions in the scene's frame list (0-based).

use crate::error::BenchError;

/// The targets and the frames inputs are drawn from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePlan {
    /// Ascending.
    pub targets: Vec<usize>,
    /// Ascending: every frame that is not a target.
    pub pool: Vec<usize>,
}

/// Default targets of a scene of `frames` frames: every fifth frame from frame 2 (2, 7, 12, ...), excluding the
/// last two frames so each target has inputs after it.
pub fn default_targets(frames: usize) -> Vec<usize> {
    (2..frames.saturating_sub(2)).step_by(5).collect()
}

/// The plan for a scene of `frames` frames and the given (or default) targets.
pub fn plan_frames(frames: usize, targets: Option<&[usize]>) -> Result<FramePlan, BenchError> {
    let mut targets = targets.map(<[usize]>::to_vec).unwrap_or_else(|| default_targets(frames));
    targets.sort_unstable();
    targets.dedup();
    if targets.is_empty() {
        return Err(BenchError::setting(
            "target frames",
            format!("none: a scene of {frames} frames needs at least 5 frames for the default targets"),
        ));
    }
    if let Some(&bad) = targets.iter().find(|&&t| t == 0 || t + 1 >= frames) {
        return Err(BenchError::setting(
            "target frames",
            format!("{bad} is not strictly inside the scene's frames 0..{frames} (inputs must bracket targets)"),
        ));
    }
    let pool = (0..frames).filter(|f| targets.binary_search(f).is_err()).collect();
    Ok(FramePlan { targets, pool })
}

/// An input frame count the plan cannot give: between 2 and the frames that are not targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{requested} input frames requested, but {available} non-target frames are available (2 to {available})")]
pub struct InputFrameCount {
    pub requested: usize,
    pub available: usize,
}

impl FramePlan {
    /// `count` input frames spread evenly over the pool, the first and last included; an error naming the
    /// largest possible count when the pool is too small.
    pub fn inputs(&self, count: usize) -> Result<Vec<usize>, InputFrameCount> {
        let available = self.pool.len();
        if count < 2 || count > available {
            return Err(InputFrameCount { requested: count, available });
        }
        let last = (available - 1) as f64;
        let picked: Vec<usize> =
            (0..count).map(|i| self.pool[(i as f64 * last / (count - 1) as f64).round() as usize]).collect();
        Ok(picked)
    }
}
