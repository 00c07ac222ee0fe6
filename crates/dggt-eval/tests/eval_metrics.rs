//! The evaluation's pure pieces on constructed cases: aligned depth RMSE, STORM's scene-flow metrics, the
//! bilinear sampling and cell mapping, the protocols' frame plans and the aggregation.

use dggt_data::Preprocess;
use dggt_eval::grid::{CellMapping, cell_has_sky};
use dggt_eval::metrics::{mean_present, sample_bilinear};
use dggt_eval::report::{ViewRecord, summarise_views};
use dggt_eval::{FlowMetrics, MetricError, Protocol, ProtocolKind, Split, aligned_depth_rmse, scene_flow_metrics};
use dggt_geom::ImageSize;

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

#[test]
fn depth_that_is_an_affine_function_of_the_truth_scores_zero() {
    let truth: Vec<f32> = (0..50).map(|i| 2.0 + 0.7 * i as f32).collect();
    // The network's depth is the truth at a third of the scale, shifted.
    let predicted: Vec<f32> = truth.iter().map(|g| (g - 1.5) / 3.0).collect();
    let fit = aligned_depth_rmse(&predicted, &truth).unwrap();
    assert!(fit.rmse < 1e-5, "{fit:?}");
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
    // Static points (and small motions) are accurate; the moving one is not.
    assert!(close(m.acc5, 2.0 / 3.0, 1e-12) && close(m.acc10, 2.0 / 3.0, 1e-12), "{m:?}");
    // The zero vector has no direction: its angular error is pi/2.
    assert!(close(m.angle_error_rad.unwrap(), std::f64::consts::FRAC_PI_2, 1e-12), "{m:?}");
    // Only static truth: no angle at all, and every point exact.
    let still = scene_flow_metrics(&[[0.0; 3]; 2], &[[0.0; 3]; 2]).unwrap();
    assert_eq!(
        still,
        FlowMetrics { epe3d: 0.0, acc5: 1.0, acc10: 1.0, angle_error_rad: None, points: 2, angle_points: 0 }
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
fn cells_map_through_the_resize_and_crop() {
    // 160x112 at width 112: resized 112x84 (scale 0.7, 0.75), no crop.
    let preprocess = Preprocess { target_width: 112, patch_size: 14, crop_to_square: true };
    let plan = preprocess.plan(ImageSize { width: 160, height: 112 }).unwrap();
    let mapping = CellMapping::new(&plan);
    let (x, y) = mapping.cell_centre(0, 0);
    assert!(close(x, 2.0 * 0.7, 1e-12) && close(y, 2.0 * 0.75, 1e-12));
    let (x, y) = mapping.cell_centre(27, 39);
    assert!(close(x, 158.0 * 0.7, 1e-12) && close(y, 110.0 * 0.75, 1e-12));
    // A tall image is cropped from the top: its top cells fall outside the view.
    let plan = preprocess.plan(ImageSize { width: 80, height: 160 }).unwrap();
    assert!(plan.crop_top > 0);
    let mapping = CellMapping::new(&plan);
    let map = vec![1.0f32; mapping.width * mapping.height];
    assert_eq!(mapping.sample(&map, 0, 0), None);
    assert_eq!(mapping.sample(&map, 20, 10), Some(1.0));
}

#[test]
fn a_cell_with_any_sky_pixel_is_sky() {
    let (w, h) = (8, 8);
    let mut mask = vec![0u8; w * h];
    mask[5 * w + 6] = 255; // pixel (col 6, row 5): cell (1, 1)
    assert!(cell_has_sky(&mask, w, h, 1, 1));
    assert!(!cell_has_sky(&mask, w, h, 0, 1) && !cell_has_sky(&mask, w, h, 1, 0));
    mask[5 * w + 6] = 127; // below the binarisation threshold
    assert!(!cell_has_sky(&mask, w, h, 1, 1));
}

#[test]
fn protocols_plan_their_frames() {
    let paper = Protocol::paper();
    paper.validate().unwrap();
    assert_eq!(paper.input_frames(), vec![0, 5, 10, 15]);
    let targets = paper.targets();
    assert_eq!(targets.len(), 20);
    assert_eq!(targets.iter().filter(|(_, s)| *s == Split::Reconstruction).count(), 4);
    assert_eq!(targets.iter().filter(|(_, s)| *s == Split::NovelView).count(), 16);
    assert_eq!(paper.splits(), vec![Split::Reconstruction, Split::NovelView]);

    let reconstruction = Protocol::reconstruction(3, 4, vec![0]);
    assert_eq!(reconstruction.input_frames(), vec![3, 4, 5, 6]);
    assert_eq!(reconstruction.splits(), vec![Split::Reconstruction]);

    let interpolation = Protocol::interpolation(2, 7, 3, vec![1, 0]);
    interpolation.validate().unwrap();
    assert_eq!(interpolation.input_frames(), vec![2, 5, 8]);
    assert_eq!(interpolation.targets()[1], (3, Split::Interpolated));
    assert_eq!(interpolation.splits(), vec![Split::Reconstruction, Split::Interpolated]);

    // A stride that does not end on the window's last frame: the frames after the last input are extrapolated,
    // not "between inputs"; a stride that leaves one input is refused.
    let beyond = Protocol::interpolation(0, 20, 6, vec![0]);
    beyond.validate().unwrap();
    assert_eq!(beyond.input_frames(), vec![0, 6, 12, 18]);
    assert_eq!(
        &beyond.targets()[17..],
        &[(17, Split::Interpolated), (18, Split::Reconstruction), (19, Split::Extrapolated)]
    );
    assert_eq!(beyond.splits(), vec![Split::Reconstruction, Split::Interpolated, Split::Extrapolated]);
    assert!(Split::Extrapolated.title().contains("beyond the last input"));

    let error = |p: Protocol| p.validate().unwrap_err().to_string();
    assert!(error(Protocol::interpolation(0, 20, 30, vec![0])).contains("give 1..=19"));
    assert!(error(Protocol { every: 3, ..Protocol::paper() }).contains("--every"));
    assert!(error(Protocol::interpolation(0, 5, 0, vec![0])).contains("--every"));
    assert!(error(Protocol::reconstruction(0, 0, vec![0])).contains("--frames"));
    assert!(error(Protocol::reconstruction(0, 4, vec![0, 0])).contains("twice"));
    assert!(error(Protocol::reconstruction(0, 4, vec![])).contains("--cameras"));

    let scene = std::path::Path::new("/data/scene-7");
    let message = paper.check_frames(scene, &(0..12).collect::<Vec<_>>()).unwrap_err().to_string();
    assert!(message.contains("/data/scene-7") && message.contains("too few frames"), "{message}");
    assert!(message.contains("12 frames (0..=11)"), "{message}");
    paper.check_frames(scene, &(0..25).collect::<Vec<_>>()).unwrap();
    assert_eq!(paper.kind, ProtocolKind::Paper);
}

fn record(split: Split, psnr: f64, d_rmse: Option<f64>) -> ViewRecord {
    ViewRecord {
        frame: 0,
        camera: 0,
        camera_name: "FRONT".into(),
        split,
        scene_time: 0.0,
        psnr,
        ssim: 0.5,
        lpips: None,
        d_rmse,
        depth_scale: None,
        depth_shift: None,
        depth_cells: 0,
        depth_note: None,
        motion: None,
        refined: None,
    }
}

#[test]
fn split_means_leave_out_missing_metrics() {
    let views = [
        record(Split::Reconstruction, 20.0, Some(1.0)),
        record(Split::Reconstruction, 30.0, None),
        record(Split::NovelView, 10.0, Some(4.0)),
    ];
    let s = summarise_views(&views, Split::Reconstruction);
    assert_eq!((s.count, s.d_rmse_count, s.motion_count), (2, 1, 0));
    assert_eq!((s.psnr, s.d_rmse, s.lpips, s.epe3d), (Some(25.0), Some(1.0), None, None));
    let s = summarise_views(&views, Split::NovelView);
    assert_eq!((s.count, s.psnr, s.d_rmse), (1, Some(10.0), Some(4.0)));
    assert_eq!(mean_present([None, None]), (None, 0));
}
