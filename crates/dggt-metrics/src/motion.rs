//! 3D motion (STORM's `compute_scene_flow_metrics`, Yang et al., ICLR 2025), over the points given, with
//! `e_i = |p_i - g_i|` the end-point error of predicted flow `p_i` against ground truth `g_i` and
//! `r_i = e_i / (|g_i| + 1e-20)` the relative error:
//! - EPE3D: `mean_i e_i`;
//! - Acc5 (strict): the fraction of points with `e_i < 0.05` or `r_i < 0.05`;
//! - Acc10 (relaxed): the fraction with `e_i < 0.1` or `r_i < 0.1`;
//! - moving EPE3D: `mean_i e_i` over the points whose true flow is longer than 0.1 (the moving points, where
//!   holding everything still is no answer; not in STORM);
//! - angular error: over the points whose true flow is longer than 0.1 (shorter ones have no reliable
//!   direction), the mean of `acos(clamp(u(p) . u(g), -1 + 1e-7, 1 - 1e-7))` in radians, with
//!   `u(v) = v / (|v| + 1e-7)`. A zero prediction thus has an angular error of exactly pi/2 (its unit vector is
//!   zero), and a perfect one about 4.5e-4 rad (the clamp), as in STORM.
//!
//! The flow is compared in the units the export stores (world-frame velocity in m/s for this project's
//! exports and STORM's Waymo flow), so the 0.05 / 0.1 thresholds apply to those values. Accuracies are
//! fractions in `[0, 1]` here; reports show them in percent.

use serde::Serialize;

use crate::error::{MetricError, check_lengths};

/// Absolute end-point error below which a point counts for Acc5.
pub const STRICT_EPE: f64 = 0.05;
/// Relative error below which a point counts for Acc5.
pub const STRICT_RELATIVE: f64 = 0.05;
/// Absolute end-point error below which a point counts for Acc10.
pub const RELAXED_EPE: f64 = 0.1;
/// Relative error below which a point counts for Acc10.
pub const RELAXED_RELATIVE: f64 = 0.1;
/// True flow at least this long has a direction for the angular error.
pub const ANGLE_MIN_FLOW: f64 = 0.1;
/// Added to the norms before normalising, and the margin of the cosine clamp, in the angular error.
const ANGLE_EPSILON: f64 = 1e-7;
/// Added to the true flow's norm in the relative error.
const RELATIVE_EPSILON: f64 = 1e-20;

/// Scene-flow metrics of one view.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FlowMetrics {
    /// Mean end-point error (units of the stored flow).
    pub epe3d: f64,
    /// Fraction of points within the strict threshold (Acc5).
    pub acc5: f64,
    /// Fraction of points within the relaxed threshold (Acc10).
    pub acc10: f64,
    /// Mean end-point error over the points whose true flow is longer than [`ANGLE_MIN_FLOW`] (the moving
    /// points); `None` when there are none.
    pub moving_epe3d: Option<f64>,
    /// Mean angular error in radians; `None` when no true flow is longer than [`ANGLE_MIN_FLOW`].
    pub angle_error_rad: Option<f64>,
    /// Points scored for EPE3D and the accuracies.
    pub points: usize,
    /// Points scored for the angular error.
    pub angle_points: usize,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn widen(v: [f32; 3]) -> [f64; 3] {
    v.map(f64::from)
}

/// EPE3D, Acc5, Acc10 and the angular error of `predicted` flow against `truth` (paired points).
pub fn scene_flow_metrics(predicted: &[[f32; 3]], truth: &[[f32; 3]]) -> Result<FlowMetrics, MetricError> {
    const METRIC: &str = "scene flow";
    check_lengths(METRIC, predicted.len(), truth.len())?;
    for (which, values) in [("predicted", predicted), ("true", truth)] {
        if let Some(index) = values.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            return Err(MetricError::NonFinite { metric: METRIC, which, index });
        }
    }
    let (mut epe_sum, mut strict, mut relaxed) = (0.0, 0usize, 0usize);
    let (mut angle_sum, mut moving_epe_sum, mut angle_points) = (0.0, 0.0, 0usize);
    for (&p, &g) in predicted.iter().zip(truth) {
        let (p, g) = (widen(p), widen(g));
        let error = norm([p[0] - g[0], p[1] - g[1], p[2] - g[2]]);
        let truth_norm = norm(g);
        let relative = error / (truth_norm + RELATIVE_EPSILON);
        epe_sum += error;
        strict += usize::from(error < STRICT_EPE || relative < STRICT_RELATIVE);
        relaxed += usize::from(error < RELAXED_EPE || relative < RELAXED_RELATIVE);
        if truth_norm > ANGLE_MIN_FLOW {
            let (pn, gn) = (norm(p) + ANGLE_EPSILON, truth_norm + ANGLE_EPSILON);
            let cosine = (p[0] * g[0] + p[1] * g[1] + p[2] * g[2]) / (pn * gn);
            angle_sum += cosine.clamp(-1.0 + ANGLE_EPSILON, 1.0 - ANGLE_EPSILON).acos();
            moving_epe_sum += error;
            angle_points += 1;
        }
    }
    let n = truth.len() as f64;
    Ok(FlowMetrics {
        epe3d: epe_sum / n,
        acc5: strict as f64 / n,
        acc10: relaxed as f64 / n,
        moving_epe3d: (angle_points > 0).then(|| moving_epe_sum / angle_points as f64),
        angle_error_rad: (angle_points > 0).then(|| angle_sum / angle_points as f64),
        points: truth.len(),
        angle_points,
    })
}
