//! Depth: D-RMSE. The network predicts depth up to an unknown scale, so the rendered expected depth `d`
//! is first aligned to the lidar depth `g` by the least-squares scale and shift `(a, b)` minimising
//! `sum_i (a d_i + b - g_i)^2` over the cells given, and D-RMSE is `sqrt(mean_i (a d_i + b - g_i)^2)` in
//! metres. The scale may come out negative (the fit is unconstrained). When every prediction is the same
//! value the scale is undetermined; the fit then takes `a = 0`, `b = mean(g)`, its minimiser with the least
//! scale, so the RMSE is the standard deviation of the truth. Which cells take part (not sky, a positive lidar
//! depth, inside the rendered image) is the caller's choice; the evaluation samples them on a grid of lidar
//! cells. AbsRel is `mean_i |a d_i + b - g_i| / g_i` under the same alignment (the truth must be positive), so it is
//! as blind to the network's scale as D-RMSE is.

use serde::Serialize;

use crate::error::{MetricError, check_lengths};

/// D-RMSE after the least-squares scale-and-shift alignment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthAlignment {
    /// Root mean square error of `scale * predicted + shift` against the truth (metres).
    pub rmse: f64,
    /// Mean absolute error of `scale * predicted + shift` relative to the truth.
    pub abs_rel: f64,
    pub scale: f64,
    pub shift: f64,
    /// Cells scored.
    pub cells: usize,
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
    if let Some(index) = truth.iter().position(|&g| g <= 0.0) {
        return Err(MetricError::NonPositiveTruth { metric: METRIC, index, value: truth[index] });
    }
    let errors =
        predicted.iter().zip(truth).map(|(&p, &g)| (scale * f64::from(p) + shift - f64::from(g), f64::from(g)));
    let (squared, relative) = errors.fold((0.0, 0.0), |(sq, rel), (e, g)| (sq + e * e, rel + e.abs() / g));
    Ok(DepthAlignment { rmse: (squared / n).sqrt(), abs_rel: relative / n, scale, shift, cells: truth.len() })
}

impl DepthAlignment {
    /// AbsRel of the cells `(predicted, truth)` under this alignment (a part of the cells it was fitted on, such
    /// as those at depth edges); `None` for no cells.
    pub fn abs_rel_of(&self, cells: impl Iterator<Item = (f32, f32)>) -> Option<f64> {
        let (sum, count) = cells.fold((0.0, 0usize), |(sum, count), (p, g)| {
            let g = f64::from(g);
            (sum + (self.scale * f64::from(p) + self.shift - g).abs() / g, count + 1)
        });
        (count > 0).then(|| sum / count as f64)
    }
}
