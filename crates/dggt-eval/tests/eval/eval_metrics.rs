//! The evaluation's pure pieces on constructed cases: the cell mapping, the protocols' frame plans and the
//! aggregation.

use dggt_data::Preprocess;
use dggt_eval::grid::{CellMapping, CellSampling, cell_has_sky};
use dggt_eval::report::{ImageScores, SourceFlowMetrics, SourcePsnr, ViewRecord, summarise_views};
use dggt_eval::{Protocol, ProtocolKind, TargetKind};
use dggt_geom::ImageSize;
use dggt_metrics::FlowMetrics;

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance
}

#[test]
fn cells_map_through_the_resize_and_crop() {
    // 160x112 at width 112: resized 112x84 (scale 0.7, 0.75), no crop.
    let preprocess = Preprocess { target_width: 112, patch_size: 14, crop_to_square: true };
    let plan = preprocess.plan(ImageSize { width: 160, height: 112 }).unwrap();
    let mapping = CellMapping::new(&plan, CellSampling::Pixel);
    let (x, y) = mapping.cell_centre(0, 0);
    assert!(close(x, 2.0 * 0.7, 1e-12) && close(y, 2.0 * 0.75, 1e-12));
    let (x, y) = mapping.cell_centre(27, 39);
    assert!(close(x, 158.0 * 0.7, 1e-12) && close(y, 110.0 * 0.75, 1e-12));
    // A tall image is cropped from the top: its top cells fall outside the view.
    let plan = preprocess.plan(ImageSize { width: 80, height: 160 }).unwrap();
    assert!(plan.crop_top > 0);
    let mapping = CellMapping::new(&plan, CellSampling::Pixel);
    let map = vec![1.0f32; mapping.width * mapping.height];
    assert_eq!(mapping.sample(&map, 0, 0), None);
    assert_eq!(mapping.sample(&map, 20, 10), Some(1.0));
}

#[test]
fn a_cell_on_a_depth_step_reads_one_surface_by_pixel_and_a_blend_bilinearly() {
    // 112x112 seen at width 56: scale 0.5, so cell (row, 7) has its centre at x = 30 * 0.5 = 15, the border
    // between network pixels 14 and 15 (centres 14.5 and 15.5); cell 6 at x = 13 (pixel 13).
    let preprocess = Preprocess { target_width: 56, patch_size: 14, crop_to_square: true };
    let plan = preprocess.plan(ImageSize { width: 112, height: 112 }).unwrap();
    let pixel = CellMapping::new(&plan, CellSampling::Pixel);
    let bilinear = CellMapping { sampling: CellSampling::Bilinear, ..pixel };
    // Near (4 m) in columns 0-14, far (20 m) from column 15 on.
    let depth: Vec<f32> =
        (0..pixel.width * pixel.height).map(|i| if i % pixel.width < 15 { 4.0 } else { 20.0 }).collect();
    assert_eq!(pixel.sample(&depth, 10, 7), Some(20.0), "the centre x = 15 falls on the far pixel 15");
    assert_eq!(bilinear.sample(&depth, 10, 7), Some(12.0), "halfway between the centres 14.5 and 15.5");
    for mapping in [pixel, bilinear] {
        assert_eq!(
            mapping.sample(&depth, 10, 6),
            Some(4.0),
            "{:?}: cell 6 lies inside the near surface",
            mapping.sampling
        );
    }
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
    assert_eq!(targets.iter().filter(|(_, s)| *s == TargetKind::Reconstruction).count(), 4);
    assert_eq!(targets.iter().filter(|(_, s)| *s == TargetKind::NovelView).count(), 16);
    assert_eq!(paper.splits(), vec![TargetKind::Reconstruction, TargetKind::NovelView]);

    let reconstruction = Protocol::reconstruction(3, 4, vec![0]);
    assert_eq!(reconstruction.input_frames(), vec![3, 4, 5, 6]);
    assert_eq!(reconstruction.splits(), vec![TargetKind::Reconstruction]);

    let interpolation = Protocol::interpolation(2, 7, 3, vec![1, 0]);
    interpolation.validate().unwrap();
    assert_eq!(interpolation.input_frames(), vec![2, 5, 8]);
    assert_eq!(interpolation.targets()[1], (3, TargetKind::Interpolated));
    assert_eq!(interpolation.splits(), vec![TargetKind::Reconstruction, TargetKind::Interpolated]);

    // A stride that does not end on the window's last frame: the frames after the last input are extrapolated,
    // not "between inputs"; a stride that leaves one input is refused.
    let beyond = Protocol::interpolation(0, 20, 6, vec![0]);
    beyond.validate().unwrap();
    assert_eq!(beyond.input_frames(), vec![0, 6, 12, 18]);
    assert_eq!(
        &beyond.targets()[17..],
        &[(17, TargetKind::Interpolated), (18, TargetKind::Reconstruction), (19, TargetKind::Extrapolated)]
    );
    assert_eq!(beyond.splits(), vec![TargetKind::Reconstruction, TargetKind::Interpolated, TargetKind::Extrapolated]);
    assert!(TargetKind::Extrapolated.title().contains("beyond the last input"));

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

#[test]
fn passes_of_a_long_window_score_every_frame_once_with_the_window_s_splits() {
    // Inputs 0, 4, ..., 36 of frames 0..39 in passes of three inputs sharing their ends; frames 2, 6, ... held out.
    let held_out: Vec<usize> = (2..40).step_by(4).collect();
    let whole =
        Protocol { scored: Some(held_out), inputs_per_pass: Some(3), ..Protocol::interpolation(0, 39, 4, vec![0, 1]) };
    whole.validate().unwrap();
    let passes = whole.passes();
    let inputs: Vec<Vec<usize>> = passes.iter().map(|p| p.protocol.input_frames()).collect();
    assert_eq!(inputs, [vec![0, 4, 8], vec![8, 12, 16], vec![16, 20, 24], vec![24, 28, 32], vec![32, 36]]);
    for pass in &passes {
        pass.protocol.validate().unwrap();
        assert_eq!(pass.protocol.cameras, [0, 1], "a pass keeps the cameras");
        assert_eq!(pass.protocol.inputs_per_pass, None, "a pass is one forward pass");
    }
    // Each frame the whole window scores is reported by exactly one pass, under the same split.
    let mut reported: Vec<(usize, TargetKind)> = passes
        .iter()
        .flat_map(|p| p.protocol.targets().into_iter().filter(|(frame, _)| p.scores.contains(frame)))
        .collect();
    reported.sort_unstable();
    assert_eq!(reported, whole.targets(), "the passes report the window's targets once each");
    assert!(reported.contains(&(38, TargetKind::Extrapolated)), "the last pass reaches the window's end");
    // One pass when the inputs fit.
    let short = Protocol { inputs_per_pass: Some(12), ..whole.clone() };
    assert_eq!(short.passes().len(), 1, "ten inputs fit a pass of twelve");
    assert_eq!(short.passes()[0].protocol, short, "the one pass is the protocol itself");
    let error = |p: Protocol| p.validate().unwrap_err().to_string();
    assert!(error(Protocol { inputs_per_pass: Some(1), ..whole }).contains("two inputs or more"));
    assert!(error(Protocol { inputs_per_pass: Some(3), ..Protocol::paper() }).contains("paper"));
}

fn record(split: TargetKind, psnr: f64, d_rmse: Option<f64>) -> ViewRecord {
    ViewRecord {
        frame: 0,
        camera: 0,
        camera_name: "FRONT".into(),
        split,
        scene_time: 0.0,
        psnr,
        ssim: 0.5,
        lpips: None,
        dynamic_psnr: None,
        dynamic_pixels: 0,
        d_rmse,
        abs_rel: d_rmse.map(|d| d / 10.0),
        depth_scale: None,
        depth_shift: None,
        depth_cells: 0,
        depth_note: None,
        depth_parts: None,
        motion: None,
        motion_by_source: Vec::new(),
        dynamic_psnr_by_source: Vec::new(),
        refined: None,
        nearest_input: None,
    }
}

fn flow(epe3d: f64) -> FlowMetrics {
    FlowMetrics {
        epe3d,
        acc5: 0.5,
        acc10: 0.75,
        moving_epe3d: None,
        angle_error_rad: None,
        points: 10,
        angle_points: 0,
    }
}

#[test]
fn motion_sources_are_averaged_side_by_side() {
    let scored = |held: f64, instances: Option<f64>| {
        let mut view = record(TargetKind::Reconstruction, 20.0, None);
        view.motion_by_source.push(SourceFlowMetrics { source: "held".into(), metrics: flow(held) });
        if let Some(epe) = instances {
            view.motion_by_source.push(SourceFlowMetrics { source: "instances".into(), metrics: flow(epe) });
        }
        view
    };
    let views = [scored(4.0, Some(1.0)), scored(2.0, None), scored(6.0, Some(2.0))];
    let s = summarise_views(&views, TargetKind::Reconstruction);
    let names: Vec<&str> = s.motion_by_source.iter().map(|m| m.source.as_str()).collect();
    assert_eq!(names, ["held", "instances"]);
    assert_eq!((s.motion_by_source[0].epe3d, s.motion_by_source[0].count), (Some(4.0), 3));
    assert_eq!((s.motion_by_source[1].epe3d, s.motion_by_source[1].count), (Some(1.5), 2));
    assert_eq!(s.motion_by_source[1].acc10, Some(0.75));
    // The record serialises each source's metrics beside its name.
    let json = serde_json::to_value(&views[0]).unwrap();
    assert_eq!(json["motion_by_source"][1]["source"], "instances");
    assert_eq!(json["motion_by_source"][1]["epe3d"], 1.0);
    // Without sources, nothing is written.
    assert!(
        serde_json::to_value(record(TargetKind::Reconstruction, 1.0, None)).unwrap().get("motion_by_source").is_none()
    );
}

#[test]
fn image_sources_are_averaged_side_by_side_over_the_views_that_have_them() {
    let drawn = |sources: &[(&str, f64)]| {
        let mut view = record(TargetKind::NovelView, 20.0, None);
        view.dynamic_psnr_by_source =
            sources.iter().map(|&(s, psnr)| SourcePsnr { source: s.into(), dynamic_psnr: psnr, count: 1 }).collect();
        view
    };
    let views =
        [drawn(&[("held", 18.0), ("cross-fade", 20.0)]), drawn(&[]), drawn(&[("held", 22.0), ("cross-fade", 23.0)])];
    let s = summarise_views(&views, TargetKind::NovelView);
    let means: Vec<(&str, f64, usize)> =
        s.dynamic_psnr_by_source.iter().map(|m| (m.source.as_str(), m.dynamic_psnr, m.count)).collect();
    assert_eq!(means, [("held", 20.0, 2), ("cross-fade", 21.5, 2)]);
    assert!(summarise_views(&views, TargetKind::Reconstruction).dynamic_psnr_by_source.is_empty());
}

#[test]
fn split_means_leave_out_missing_metrics() {
    let views = [
        record(TargetKind::Reconstruction, 20.0, Some(1.0)),
        record(TargetKind::Reconstruction, 30.0, None),
        record(TargetKind::NovelView, 10.0, Some(4.0)),
    ];
    let s = summarise_views(&views, TargetKind::Reconstruction);
    assert_eq!((s.count, s.d_rmse_count, s.motion_count), (2, 1, 0));
    assert_eq!((s.psnr, s.d_rmse, s.lpips, s.epe3d), (Some(25.0), Some(1.0), None, None));
    let s = summarise_views(&views, TargetKind::NovelView);
    assert_eq!((s.count, s.psnr, s.d_rmse), (1, Some(10.0), Some(4.0)));
}

#[test]
fn the_nearest_input_baseline_is_averaged_where_views_have_it_and_reported_beside_the_renders() {
    let copied = |psnr: f64| Some(ImageScores { psnr, ssim: 0.25, lpips: None });
    let views = [
        ViewRecord { nearest_input: copied(14.0), ..record(TargetKind::Interpolated, 20.0, Some(2.0)) },
        ViewRecord { nearest_input: copied(16.0), ..record(TargetKind::Interpolated, 22.0, Some(4.0)) },
        record(TargetKind::Reconstruction, 30.0, None),
    ];
    let between = summarise_views(&views, TargetKind::Interpolated);
    let baseline = between.nearest_input.as_ref().unwrap();
    assert_eq!((baseline.psnr, baseline.ssim, baseline.lpips), (Some(15.0), Some(0.25), None));
    assert!((between.abs_rel.unwrap() - 0.3).abs() < 1e-12, "AbsRel means like D-RMSE: {:?}", between.abs_rel);
    assert!(summarise_views(&views, TargetKind::Reconstruction).nearest_input.is_none());
}

#[test]
fn scored_frames_narrow_the_targets_to_the_held_out_ones_and_keep_the_inputs() {
    let mut protocol = Protocol::interpolation(0, 13, 4, vec![0, 1]);
    protocol.scored = Some(vec![2, 6, 10]);
    protocol.validate().unwrap();
    let frames: Vec<usize> = protocol.targets().into_iter().map(|(f, _)| f).collect();
    assert_eq!(frames, vec![0, 2, 4, 6, 8, 10, 12]);
    protocol.scored = Some(vec![4]);
    assert!(protocol.validate().unwrap_err().to_string().contains("--score-frames"), "an input is no scored frame");
    protocol.scored = Some(vec![20]);
    assert!(protocol.validate().is_err(), "outside the window");
}
