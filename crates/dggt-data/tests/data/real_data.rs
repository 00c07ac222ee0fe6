//! The readers on real driving data: one Waymo frame in the export layout and a KITTI odometry excerpt.
//! The data lives beside the repository (`../shared/real-data`, or `$DGGT_REAL_DATA`); it is licensed for
//! non-commercial research and never copied into the repository.

use std::path::PathBuf;

use dggt_data::{ExportOptions, Preprocess, prepare_view, read_export, read_kitti_odometry};
use dggt_geom::glam::DVec3;

fn real_data() -> PathBuf {
    dggt_test_data::real_data()
}

#[test]
fn waymo_export_frame_has_five_cameras_in_opencv_axes() {
    let scene = read_export(&real_data().join("waymo/export_one_frame/000"), &ExportOptions::default()).unwrap();
    assert_eq!(scene.cameras.len(), 5);
    assert_eq!(scene.frames.len(), 1);
    let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["FRONT", "FRONT_LEFT", "FRONT_RIGHT", "SIDE_LEFT", "SIDE_RIGHT"]);
    for camera in &scene.cameras[..3] {
        assert_eq!((camera.size.width, camera.size.height), (1920, 1280), "{}", camera.name);
    }
    for camera in &scene.cameras[3..] {
        assert_eq!((camera.size.width, camera.size.height), (1920, 886), "{}", camera.name);
    }
    // The world is the ego frame of frame 0 (forward-left-up). Expected optical axes in that frame:
    let expected_axis =
        [DVec3::X, DVec3::new(1.0, 1.0, 0.0).normalize(), DVec3::new(1.0, -1.0, 0.0).normalize(), DVec3::Y, -DVec3::Y];
    for (c, camera) in scene.cameras.iter().enumerate() {
        let pose = scene.view(0, c).world_from_camera;
        let rotation = pose.rotation_matrix();
        let gram = rotation.transpose() * rotation;
        assert!(gram.abs_diff_eq(dggt_geom::glam::DMat3::IDENTITY, 1e-9));
        assert!((rotation.determinant() - 1.0).abs() < 1e-9);
        let axis = pose.transform_vector(DVec3::Z);
        assert!(axis.dot(expected_axis[c]) > 0.98, "{} looks along {axis}", camera.name);
        let down = pose.transform_vector(DVec3::Y);
        assert!(down.dot(-DVec3::Z) > 0.98, "{}: image down is {down}, expected world down", camera.name);
        let centre = pose.translation();
        assert!(
            (1.9..2.3).contains(&centre.z) && (1.3..1.7).contains(&centre.x),
            "{} mounted at {centre}",
            camera.name
        );
        let k = camera.intrinsics;
        assert!((1900.0..2200.0).contains(&k.fx) && (k.fx - k.fy).abs() < 1.0, "{}: {k:?}", camera.name);
        assert!((k.cx - camera.size.width as f64 / 2.0).abs() < 50.0, "{}: {k:?}", camera.name);
        // Side cameras are the upper part of a taller sensor: their principal point is high in the image.
        let cy_range = if c < 3 { 590.0..690.0 } else { 200.0..300.0 };
        assert!(cy_range.contains(&k.cy), "{}: {k:?}", camera.name);
        assert!(camera.distortion[1] < 0.0, "Waymo lenses have barrel distortion");
    }
    let front = prepare_view(&scene, 0, 0, &Preprocess::default()).unwrap();
    assert_eq!((front.image.size.width, front.image.size.height), (518, 350));
    let side = prepare_view(&scene, 0, 3, &Preprocess::default()).unwrap();
    assert_eq!((side.image.size.width, side.image.size.height), (518, 238));
    assert!((front.intrinsics.fx - 2044.508 * 518.0 / 1920.0).abs() < 1e-2);
}

#[test]
fn kitti_sequence_moves_forward_about_1_2_metres_per_frame() {
    let root = real_data().join("kitti-odometry/sequence_1");
    let scene = read_kitti_odometry(&root, None).unwrap();
    assert_eq!(scene.frames.len(), 51);
    assert_eq!(scene.cameras[0].intrinsics.fx, 707.0912);
    assert_eq!((scene.cameras[0].size.width, scene.cameras[0].size.height), (1226, 370));
    for f in 1..scene.frames.len() {
        let a = scene.view(f - 1, 0).world_from_camera;
        let b = scene.view(f, 0).world_from_camera;
        let step = b.translation() - a.translation();
        assert!((1.0..1.4).contains(&step.length()), "frame {f}: step of {} m", step.length());
        let forward = a.transform_vector(DVec3::Z);
        assert!(step.normalize().dot(forward) > 0.95, "frame {f}: the camera moves along its optical axis");
    }
    let length = scene.trajectory_length(0);
    assert!((50.0..70.0).contains(&length), "{length}");
    assert!(scene.view(0, 0).world_from_camera.max_abs_difference(&dggt_geom::Rigid::IDENTITY) < 1e-8);

    let window = read_kitti_odometry(&root, Some(10..20)).unwrap();
    assert_eq!(window.frames.len(), 10);
    assert!(window.view(0, 0).world_from_camera.max_abs_difference(&dggt_geom::Rigid::IDENTITY) < 1e-12);
    assert!((window.frames[9].timestamp - 0.9).abs() < 1e-12);

    let view =
        prepare_view(&scene, 3, 0, &Preprocess { target_width: 518, patch_size: 14, crop_to_square: true }).unwrap();
    assert_eq!((view.image.size.width, view.image.size.height), (518, 154));
    let plane = view.image.size.area();
    let (r, g, b) = (&view.image.data[..plane], &view.image.data[plane..2 * plane], &view.image.data[2 * plane..]);
    assert!(r == g && g == b, "grayscale is replicated to RGB");
    assert!(read_kitti_odometry(&root, Some(40..60)).is_err());
}

#[test]
fn training_stream_decodes_kitti_samples_in_step_order() {
    use dggt_data::{LoaderOptions, Sampler, SamplerConfig, training_stream};
    let scene = std::sync::Arc::new(read_kitti_odometry(&real_data().join("kitti-odometry/sequence_1"), None).unwrap());
    let sampler = Sampler::new(SamplerConfig::default(), scene.frames.len(), 1).unwrap();
    let preprocess = Preprocess { target_width: 140, patch_size: 14, crop_to_square: true };
    let stream = training_stream(scene.clone(), sampler.clone(), preprocess, 11, 5, LoaderOptions::default()).unwrap();
    for (loaded, step) in stream.take(3).zip(5..) {
        let loaded = loaded.unwrap();
        assert_eq!(loaded.step, step);
        assert_eq!(loaded.sample, sampler.sample_at(11, step));
        let n = loaded.sample.input_frames.len();
        assert!((4..=8).contains(&n));
        assert_eq!((loaded.inputs.len(), loaded.targets.len()), (n, 2 * n));
        for (view, &frame) in loaded.inputs.iter().zip(&loaded.sample.input_frames) {
            assert_eq!(view.frame, frame);
            assert_eq!((view.image.size.width, view.image.size.height), (140, 42));
            assert_eq!(view.world_from_camera, scene.view(frame, 0).world_from_camera);
        }
    }
}
