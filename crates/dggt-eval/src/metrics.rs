//! The geometric metrics of one rendered view, as pure functions on host slices (the image metrics, PSNR,
//! SSIM and LPIPS, come from `dggt-losses`).
//!
//! **Depth (D-RMSE).** The network predicts depth up to an unknown scale, so the rendered expected depth `d`
//! is first aligned to the lidar depth `g` by the least-squares scale and shift `(a, b)` minimising
//! `sum_i (a d_i + b - g_i)^2` over the cells given, and D-RMSE is `sqrt(mean_i (a d_i + b - g_i)^2)` in
//! metres. The scale may come out negative (the fit is unconstrained). When every prediction is the same
//! value the scale is undetermined; the fit then takes `a = 0`, `b = mean(g)`, its minimiser with the least
//! scale, so the RMSE is the standard deviation of the truth. Which cells take part (not sky, lidar depth
//! > 0, inside the rendered image) is the caller's choice; see [`crate::grid`].
//!
//! **3D motion** (STORM's `compute_scene_flow_metrics`, Yang et al., ICLR 2025), over the points given, with
//! `e_i = |p_i - g_i|` the end-point error of predicted flow `p_i` against ground truth `g_i` and
//! `r_i = e_i / (|g_i| + 1e-20)` the relative error:
//! - EPE3D: `mean_i e_i`;
//! - Acc5 (strict): the fraction of points with `e_i < 0.05` or `r_i < 0.05`;
//! - Acc10 (relaxed): the fraction with `e_i < 0.1` or `r_i < 0.1`;
//! - angular error: over the points whose true flow is longer than 0.1 (shorter ones have no reliable
//!   direction), the mean of `acos(clamp(u(p) . u(g), -1 + 1e-7, 1 - 1e-7))` in radians, with
//!   `u(v) = v / (|v| + 1e-7)`. A zero prediction thus has an angular error of exactly pi/2 (its unit vector is
//!   zero), and a perfect one about 4.5e-4 rad (the clamp), as in STORM.
//!
//! The flow is compared in the units the export stores (world-frame velocity in m/s for this project's
//! exports and STORM's Waymo flow), so the 0.05 / 0.1 thresholds apply to those values. Accuracies are
//! fractions in `[0, 1]` here; reports show them in percent.
//!
//! Every function rejects inputs it cannot score (no points, mismatched lengths, non-finite values) with a
//! [`MetricError`] rather than returning NaN.

use serde::Serialize;

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

/// Why a metric has no value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    #[error("{metric}: no points to score")]
    Empty { metric: &'static str },
    #[error("{metric}: {predicted} predicted values for {truth} true ones")]
    LengthMismatch { metric: &'static str, predicted: usize, truth: usize },
    #[error("{metric}: non-finite {which} value at point {index}")]
    NonFinite { metric: &'static str, which: &'static str, index: usize },
}

/// D-RMSE after the least-squares scale-and-shift alignment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthAlignment {
    /// Root mean square error of `scale * predicted + shift` against the truth (metres).
    pub rmse: f64,
    pub scale: f64,
    pub shift: f64,
    /// Cells scored.
    pub cells: usize,
}

/// Scene-flow metrics of one view.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FlowMetrics {
    /// Mean end-point error (units of the stored flow).
    pub epe3d: f64,
    /// Fraction of points within the strict threshold (Acc5).
    pub acc5: f64,
    /// Fraction of points within the relaxed threshold (Acc10).
    pub acc10: f64,
    /// Mean angular error in radians; `None` when no true flow is longer than [`ANGLE_MIN_FLOW`].
    pub angle_error_rad: Option<f64>,
    /// Points scored for EPE3D and the accuracies.
    pub points: usize,
    /// Points scored for the angular error.
    pub angle_points: usize,
}

fn check_lengths(metric: &'static str, predicted: usize, truth: usize) -> Result<(), MetricError> {
    if predicted != truth {
        return Err(MetricError::LengthMismatch { metric, predicted, truth });
    }
    if truth == 0 {
        return Err(MetricError::Empty { metric });
    }
    Ok(())
}

/// D-RMSE of `predicted` against `truth` (paired cells) after the least-squares scale and shift.
pub fn aligned_depth_rmse(predicted: &[f32], truth: &[f32]) -> Result<DepthAlignment, MetricError> {
    const METRIC: &str = "D-RMSE";
    check_lengths(METRIC, predicted.len(), truth.len())?;
    for (which, values) in [("predicted", predicted), ("true", truth)] {
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(MetricError::NonFinite { metric: METRIC, which, index });
        }
    }
    let n = truth.len() as f64;
    let mean_p = predicted.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let mean_g = truth.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let (mut var_p, mut cov) = (0.0, 0.0);
    for (&p, &g) in predicted.iter().zip(truth) {
        let dp = f64::from(p) - mean_p;
        var_p += dp * dp;
        cov += dp * (f64::from(g) - mean_g);
    }
    // A spread below f32 resolution of the values is no spread: the scale is undetermined.
    let resolution = f64::from(f32::EPSILON) * mean_p.abs().max(1e-30);
    let scale = if var_p > n * resolution * resolution { cov / var_p } else { 0.0 };
    let shift = mean_g - scale * mean_p;
    let squared: f64 =
        predicted.iter().zip(truth).map(|(&p, &g)| (scale * f64::from(p) + shift - f64::from(g)).powi(2)).sum();
    Ok(DepthAlignment { rmse: (squared / n).sqrt(), scale, shift, cells: truth.len() })
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
    let (mut angle_sum, mut angle_points) = (0.0, 0usize);
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
            angle_points += 1;
        }
    }
    let n = truth.len() as f64;
    Ok(FlowMetrics {
        epe3d: epe_sum / n,
        acc5: strict as f64 / n,
        acc10: relaxed as f64 / n,
        angle_error_rad: (angle_points > 0).then(|| angle_sum / angle_points as f64),
        points: truth.len(),
        angle_points,
    })
}

/// The value of a row-major `width x height` map at continuous image coordinates `(x, y)` (pixel `(c, r)`
/// has its centre at `(c + 0.5, r + 0.5)`), bilinear between the four nearest pixel centres, with the edge
/// pixels extended to the image border. `None` outside `[0, width] x [0, height]` or for a map of the wrong
/// length.
pub fn sample_bilinear(map: &[f32], width: usize, height: usize, x: f64, y: f64) -> Option<f32> {
    if width == 0 || height == 0 || map.len() != width * height {
        return None;
    }
    if !(0.0..=width as f64).contains(&x) || !(0.0..=height as f64).contains(&y) {
        return None;
    }
    let (u, v) = (x - 0.5, y - 0.5);
    let (c0, r0) = (u.floor(), v.floor());
    let (fu, fv) = (u - c0, v - r0);
    let clamp_col = |c: f64| c.clamp(0.0, (width - 1) as f64) as usize;
    let clamp_row = |r: f64| r.clamp(0.0, (height - 1) as f64) as usize;
    let (ca, cb, ra, rb) = (clamp_col(c0), clamp_col(c0 + 1.0), clamp_row(r0), clamp_row(r0 + 1.0));
    let at = |r: usize, c: usize| f64::from(map[r * width + c]);
    let top = at(ra, ca) * (1.0 - fu) + at(ra, cb) * fu;
    let bottom = at(rb, ca) * (1.0 - fu) + at(rb, cb) * fu;
    Some((top * (1.0 - fv) + bottom * fv) as f32)
}

/// Mean of the values present, and how many there were; `None` when there are none.
pub fn mean_present(values: impl IntoIterator<Item = Option<f64>>) -> (Option<f64>, usize) {
    let (sum, count) = values.into_iter().flatten().fold((0.0, 0usize), |(sum, count), value| (sum + value, count + 1));
    ((count > 0).then(|| sum / count as f64), count)
}
