//! The scores on constructed cases: aligned depth RMSE, STORM's scene-flow metrics and the sampling of maps
//! (bilinear, and the pixel a point falls on).

use dggt_metrics::{
    FlowMetrics, MetricError, aligned_depth_rmse, mean_present, sample_bilinear, sample_pixel, scene_flow_metrics,
};

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

#[test]
fn depth_that_is_an_affine_function_of_the_truth_scores_zero() {
    let truth: Vec<f32> = (0..50).map(|i| 2.0 + 0.7 * i as f32).collect();
    // The network's depth is the truth at a third of the scale, shifted.
    let predicted: Vec<f32> = truth.iter().map(|g| (g - 1.5) / 3.0).collect();
    let fit = aligned_depth_rmse(&predicted, &truth).unwrap();
    assert!(fit.rmse < 1e-5 && fit.abs_rel < 1e-5, "{fit:?}");
    assert!(close(fit.scale, 3.0, 1e-5) && close(fit.shift, 1.5, 1e-4), "{fit:?}");
    assert_eq!(fit.cells, 50);
}

#[test]
fn depth_residuals_give_the_expected_rmse() {
    // Two clusters: the best affine fit passes through each cluster's mean, leaving +-1 residuals.
    let predicted = [1.0f32, 1.0, 2.0, 2.0];
    let truth = [9.0f32, 11.0, 19.0, 21.0];
    let fit = aligned_depth_rmse(&predicted, &truth).unwrap();
    assert!(close(fit.scale, 10.0, 1e-9) && close(fit.shift, 0.0, 1e-9), "{fit:?}");
    assert!(close(fit.rmse, 1.0, 1e-9), "{fit:?}");
    // Residuals -1, +1, -1, +1 against 9, 11, 19, 21.
    let abs_rel = (1.0 / 9.0 + 1.0 / 11.0 + 1.0 / 19.0 + 1.0 / 21.0) / 4.0;
    assert!(close(fit.abs_rel, abs_rel, 1e-9), "{fit:?}");
    // The parts of the cells under the same fit: the first two, the last two, none.
    let cells = || predicted.iter().copied().zip(truth.iter().copied());
    let near = fit.abs_rel_of(cells().take(2)).unwrap();
    let far = fit.abs_rel_of(cells().skip(2)).unwrap();
    assert!(close(near, (1.0 / 9.0 + 1.0 / 11.0) / 2.0, 1e-9), "AbsRel of the near cluster: {near}");
    assert!(close(far, (1.0 / 19.0 + 1.0 / 21.0) / 2.0, 1e-9), "AbsRel of the far cluster: {far}");
    assert!(close((near + far) / 2.0, fit.abs_rel, 1e-9), "equal parts average to the whole");
    assert_eq!(fit.abs_rel_of(cells().skip(4)), None, "no cells, no AbsRel");
    // A constant prediction explains nothing: the RMSE is the truth's standard deviation.
    let fit = aligned_depth_rmse(&[0.0; 4], &truth).unwrap();
    assert_eq!(fit.scale, 0.0);
    assert!(close(fit.rmse, 26f64.sqrt(), 1e-9), "{fit:?}");
    assert!(fit.rmse.is_finite());
}

#[test]
fn degenerate_depth_inputs_are_errors_not_nan() {
    assert_eq!(aligned_depth_rmse(&[], &[]), Err(MetricError::Empty { metric: "D-RMSE" }));
    assert!(matches!(aligned_depth_rmse(&[1.0], &[1.0, 2.0]), Err(MetricError::LengthMismatch { .. })));
    assert!(matches!(
        aligned_depth_rmse(&[1.0, 2.0], &[1.0, 0.0]),
        Err(MetricError::NonPositiveTruth { index: 1, .. })
    ));
    assert!(matches!(
        aligned_depth_rmse(&[1.0, f32::NAN], &[1.0, 2.0]),
        Err(MetricError::NonFinite { which: "predicted", index: 1, .. })
    ));
    // One cell: the fit is exact.
    let fit = aligned_depth_rmse(&[3.0], &[7.0]).unwrap();
    assert_eq!(fit.rmse, 0.0);
}

#[test]
fn flow_errors_give_the_expected_storm_metrics() {
    let truth = [[1.0f32, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, 3.0, 0.0], [0.02, 0.0, 0.0]];
    let predicted = [
        [1.04f32, 0.0, 0.0], // EPE 0.04: strict
        [0.0, 0.0, 2.15],    // EPE 0.15, relative 7.5 %: relaxed only
        [0.0, 3.0, 0.6],     // EPE 0.6, relative 20 %: neither
        [0.0, 0.0, 0.0],     // EPE 0.02: strict; true flow too short for an angle
    ];
    let m = scene_flow_metrics(&predicted, &truth).unwrap();
    assert!(close(m.epe3d, (0.04 + 0.15 + 0.6 + 0.02) / 4.0, 1e-6), "{m:?}");
    assert!(close(m.acc5, 0.5, 1e-12) && close(m.acc10, 0.75, 1e-12), "{m:?}");
    assert_eq!((m.points, m.angle_points), (4, 3));
    // The moving points are the three whose true flow is longer than 0.1.
    assert!(close(m.moving_epe3d.unwrap(), (0.04 + 0.15 + 0.6) / 3.0, 1e-6), "{m:?}");
    // Angles: about 0, 0 and atan(0.6 / 3); the first two are not quite 0 (the 1e-7 added to the norms and
    // the cosine clamp leave under 1e-3 rad each).
    let expected = (0.2f64).atan() / 3.0;
    assert!(close(m.angle_error_rad.unwrap(), expected, 5e-4), "{m:?} vs {expected}");
}

#[test]
fn a_held_prediction_scores_as_storm_scores_zero_flow() {
    let truth = [[3.0f32, 4.0, 0.0], [0.0, 0.0, 0.0], [0.03, 0.0, 0.0]];
    let m = scene_flow_metrics(&[[0.0; 3]; 3], &truth).unwrap();
    assert!(close(m.epe3d, (5.0 + 0.0 + 0.03) / 3.0, 1e-6), "{m:?}");
    // Over the moving point alone, holding is all error.
    assert!(close(m.moving_epe3d.unwrap(), 5.0, 1e-6), "{m:?}");
    // Static points (and small motions) are accurate; the moving one is not.
    assert!(close(m.acc5, 2.0 / 3.0, 1e-12) && close(m.acc10, 2.0 / 3.0, 1e-12), "{m:?}");
    // The zero vector has no direction: its angular error is pi/2.
    assert!(close(m.angle_error_rad.unwrap(), std::f64::consts::FRAC_PI_2, 1e-12), "{m:?}");
    // Only static truth: no angle at all, and every point exact.
    let still = scene_flow_metrics(&[[0.0; 3]; 2], &[[0.0; 3]; 2]).unwrap();
    assert_eq!(
        still,
        FlowMetrics {
            epe3d: 0.0,
            acc5: 1.0,
            acc10: 1.0,
            moving_epe3d: None,
            angle_error_rad: None,
            points: 2,
            angle_points: 0
        }
    );
    assert_eq!(scene_flow_metrics(&[], &[]), Err(MetricError::Empty { metric: "scene flow" }));
    assert!(matches!(
        scene_flow_metrics(&[[0.0, f32::INFINITY, 0.0]], &[[0.0; 3]]),
        Err(MetricError::NonFinite { which: "predicted", .. })
    ));
}

#[test]
fn bilinear_sampling_uses_pixel_centres() {
    // 2x2 map: value = 10 col + row.
    let map = [0.0f32, 10.0, 1.0, 11.0];
    assert_eq!(sample_bilinear(&map, 2, 2, 0.5, 0.5), Some(0.0));
    assert_eq!(sample_bilinear(&map, 2, 2, 1.5, 1.5), Some(11.0));
    assert_eq!(sample_bilinear(&map, 2, 2, 1.0, 1.0), Some(5.5));
    // Edges extend to the border; outside is None.
    assert_eq!(sample_bilinear(&map, 2, 2, 0.0, 0.0), Some(0.0));
    assert_eq!(sample_bilinear(&map, 2, 2, 2.0, 0.5), Some(10.0));
    assert_eq!(sample_bilinear(&map, 2, 2, 2.01, 0.5), None);
    assert_eq!(sample_bilinear(&map, 2, 2, 0.5, -0.1), None);
    assert_eq!(sample_bilinear(&map, 3, 2, 0.5, 0.5), None, "wrong map length");
}

#[test]
fn means_leave_out_missing_values() {
    assert_eq!(mean_present([None, None]), (None, 0));
    assert_eq!(mean_present([Some(1.0), None, Some(3.0)]), (Some(2.0), 2));
}

/// 3 x 2: a depth step between columns 0 and 1.
const STEP: [f32; 6] = [2.0, 10.0, 10.0, 2.0, 10.0, 10.0];

#[test]
fn a_pixel_sample_reads_the_surface_the_point_falls_on_where_bilinear_blends_the_step() {
    assert_eq!(sample_pixel(&STEP, 3, 2, 0.9, 0.5), Some(2.0), "x 0.9 lies in pixel 0");
    assert_eq!(sample_pixel(&STEP, 3, 2, 1.1, 1.5), Some(10.0), "x 1.1 lies in pixel 1");
    let blended = sample_bilinear(&STEP, 3, 2, 1.0, 0.5).expect("inside");
    assert!((blended - 6.0).abs() < 1e-6, "bilinear halfway between the centres 0.5 and 1.5: {blended}");
}

#[test]
fn a_pixel_sample_takes_the_far_border_and_refuses_what_lies_outside() {
    assert_eq!(sample_pixel(&STEP, 3, 2, 3.0, 2.0), Some(10.0), "the far corner belongs to the last pixel");
    assert_eq!(sample_pixel(&STEP, 3, 2, -0.1, 1.0), None, "left of the image");
    assert_eq!(sample_pixel(&STEP, 3, 2, 1.0, 2.1), None, "below the image");
    assert_eq!(sample_pixel(&STEP[..5], 3, 2, 1.0, 1.0), None, "a map of the wrong length");
}
