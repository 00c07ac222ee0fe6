//! One synthetic scene written in every export variant and read back: the reader must recover the same cameras,
//! times and lidar points whatever the variant's axes, pose files and lidar rows, and must tell the variants
//! apart from their files alone.

use std::path::Path;

use dggt_data::lidar::project_to_depth;
use dggt_data::{DepthSource, ExportOptions, ExportVariant, Scene, SceneSource, read_export};
use dggt_geom::glam::DVec3;
use dggt_synth::{SynthConfig, generate, write_export};

fn config() -> SynthConfig {
    SynthConfig { seed: 5, frames: 4, cameras: 3, width: 64, height: 48 }
}

fn write_all() -> (tempfile::TempDir, Vec<(ExportVariant, Scene)>) {
    let dir = tempfile::tempdir().unwrap();
    let scene = generate(&config()).unwrap();
    let read = ExportVariant::ALL
        .into_iter()
        .map(|variant| {
            let root = dir.path().join(variant.name());
            write_export(&scene, &root, variant, dggt_synth::Sweeps::Write).unwrap();
            (variant, read_export(&root, &ExportOptions::default()).unwrap())
        })
        .collect();
    (dir, read)
}

#[test]
fn every_variant_gives_the_same_cameras_times_and_lidar() {
    let (_dir, scenes) = write_all();
    let (_, reference) = &scenes[0];
    let reference_points = reference.lidar[2].as_ref().unwrap().read_in_world().unwrap();
    for (variant, scene) in &scenes {
        assert_eq!(scene.source, SceneSource::Export(*variant), "detected from the files");
        assert_eq!(scene.views.len(), reference.views.len());
        for (view, expected) in scene.views.iter().zip(&reference.views) {
            let error = view.world_from_camera.max_abs_difference(&expected.world_from_camera);
            assert!(error < 1e-6, "{variant}: camera {} frame {} differs by {error}", view.camera, view.frame);
            assert!(view.files.dynamic_mask.as_ref().is_some_and(|p| p.is_file()), "{variant}: dynamic mask");
        }
        for (camera, expected) in scene.cameras.iter().zip(&reference.cameras) {
            assert_eq!(camera.intrinsics, expected.intrinsics);
            assert_eq!(camera.name, variant.camera_name(camera.id));
        }
        let times: Vec<f64> = scene.frames.iter().map(|f| f.timestamp).collect();
        let expected: Vec<f64> = (0..4).map(SynthConfig::frame_time).collect();
        assert_eq!(times, expected, "{variant}: timestamps.txt");
        let points = scene.lidar[2].as_ref().unwrap().read_in_world().unwrap();
        assert_eq!(points.len(), reference_points.len());
        let worst = points.iter().zip(&reference_points).map(|(a, b)| a.distance(*b)).fold(0.0, f64::max);
        assert!(worst < 1e-4, "{variant}: lidar points differ by up to {worst} m");
    }
    assert_eq!(scenes[2].1.cameras[0].name, "CAM_FRONT");
    assert_eq!(scenes[3].1.cameras[2].name, "ring_front_right");
}

#[test]
fn lidar_depth_lands_where_the_camera_sees_the_same_surface() {
    let (_dir, scenes) = write_all();
    let truth = generate(&config()).unwrap();
    for (variant, scene) in &scenes {
        let (frame, camera) = (3, 1);
        let view = scene.view(frame, camera);
        let sweep = scene.lidar[frame].as_ref().unwrap();
        let k = scene.cameras[camera].intrinsics;
        let size = scene.cameras[camera].size;
        let depth = project_to_depth(&sweep.read_in_world().unwrap(), &view.world_from_camera.inverse(), &k, size);
        let at = truth.at(SynthConfig::frame_time(frame)).unwrap();
        let true_pose = truth.world_from_camera(frame, camera).unwrap();
        // Cast through the centre of every pixel with a return; the lidar's own depth sits within the pixel.
        let mut errors: Vec<f64> = Vec::new();
        for (i, &z) in depth.iter().enumerate().filter(|(_, z)| **z > 0.0) {
            let (u, v) = ((i % size.width as usize) as f64 + 0.5, (i / size.width as usize) as f64 + 0.5);
            let ray = DVec3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
            let Some(hit) = at.cast(true_pose.translation(), true_pose.transform_vector(ray)) else { continue };
            let cast_z = true_pose.inverse().transform_point(hit.point).z;
            errors.push((cast_z - z as f64).abs() / cast_z);
        }
        assert!(errors.len() > 100, "{variant}: {} pixels with lidar", errors.len());
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.02, "{variant}: median relative depth error {median}");
    }
}

fn remove(path: &Path) {
    let removed = if path.is_dir() { std::fs::remove_dir_all(path) } else { std::fs::remove_file(path) };
    removed.unwrap();
}

#[test]
fn variants_are_told_apart_without_the_synthetic_description() {
    let (dir, _) = write_all();
    for variant in ExportVariant::ALL {
        let root = dir.path().join(variant.name());
        remove(&root.join("synth.json"));
        assert_eq!(ExportVariant::detect(&root).unwrap(), variant);
    }
    // Without its flat dynamic masks a STORM export is told by its axes only, which are drivestudio's Waymo axes.
    let storm = dir.path().join("waymo-storm");
    remove(&storm.join("dynamic_masks"));
    assert_eq!(ExportVariant::detect(&storm).unwrap(), ExportVariant::Waymo);
    // Reading with a declared variant that does not match fails on the missing files, naming them.
    let nuscenes = dir.path().join("nuscenes");
    let options = ExportOptions { variant: Some(ExportVariant::Waymo), ..ExportOptions::default() };
    let message = read_export(&nuscenes, &options).unwrap_err().to_string();
    assert!(message.contains("ego_pose"), "{message}");
}

#[test]
fn views_without_depth_maps_take_their_depth_from_the_lidar_at_quarter_resolution() {
    let (dir, _) = write_all();
    for variant in ExportVariant::ALL {
        // Only STORM's export has depth_flows_4; the synthetic writer adds them to every variant.
        let root = dir.path().join(variant.name());
        if variant != ExportVariant::WaymoStorm {
            remove(&root.join("depth_flows_4"));
        }
        let scene = read_export(&root, &ExportOptions::default()).unwrap();
        let (frame, camera) = (2, 0);
        let map = scene.depth_map(frame, camera).unwrap().expect("every variant has lidar or depth maps");
        if variant == ExportVariant::WaymoStorm {
            assert_eq!(scene.depth_source(), Some(DepthSource::DepthFlows4));
            assert!(map.flow.is_some(), "{variant}: depth_flows_4 carries flow");
            continue;
        }
        assert_eq!(scene.depth_source(), Some(DepthSource::Lidar), "{variant}");
        assert!(map.flow.is_none(), "{variant}: lidar maps carry no flow");
        // The quarter-resolution cell holds the nearest return of its 4 x 4 full-resolution pixels.
        let view = scene.view(frame, camera);
        let size = scene.cameras[camera].size;
        let points = scene.lidar[frame].as_ref().unwrap().read_in_world().unwrap();
        let full =
            project_to_depth(&points, &view.world_from_camera.inverse(), &scene.cameras[camera].intrinsics, size);
        assert_eq!((map.size.width, map.size.height), (size.width / 4, size.height / 4));
        for (i, &cell) in map.depth.iter().enumerate() {
            let (row, col) = (i / map.size.width as usize, i % map.size.width as usize);
            let nearest = (0..16)
                .map(|k| full[(4 * row + k / 4) * size.width as usize + 4 * col + k % 4])
                .filter(|&d| d > 0.0)
                .fold(0.0f32, |best, d| if best == 0.0 { d } else { best.min(d) });
            assert_eq!(cell, nearest, "{variant}: cell ({row}, {col})");
        }
        assert!(map.depth.iter().filter(|&&d| d > 0.0).count() > 20, "{variant}: lidar cells");
    }
}
