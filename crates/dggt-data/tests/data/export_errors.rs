//! Malformed scene exports: every defect is an error that names the file at fault and what was expected.

use std::path::Path;

use dggt_data::depth_flow::write_flow_origin;
use dggt_data::{
    DataError, DecodedViews, ExportLayout, ExportOptions, FlowOrigin, Preprocess, images, npy, prepare_view,
    prepare_view_cached, read_export, text,
};
use image::{GrayImage, RgbImage};

const IDENTITY_FLU_MOUNT: [[f64; 4]; 4] =
    [[1.0, 0.0, 0.0, 1.5], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.6], [0.0, 0.0, 0.0, 1.0]];

/// A valid two-frame, one-camera export of 64x48 images.
fn write_minimal_export(root: &Path) -> ExportLayout {
    let layout = ExportLayout::new(root);
    text::write_rows(&layout.intrinsics(0), &[[50.0], [50.0], [32.0], [24.0], [0.0], [0.0], [0.0], [0.0], [0.0]])
        .unwrap();
    text::write_rows(&layout.extrinsics(0), &IDENTITY_FLU_MOUNT).unwrap();
    for t in 0..2 {
        let mut pose = IDENTITY_FLU_MOUNT;
        pose[0][3] = t as f64;
        pose[2][3] = 0.0;
        text::write_rows(&layout.ego_pose(t), &pose).unwrap();
        let image = RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8 * 4, y as u8 * 5, 128]));
        images::write_jpeg(&layout.image(t, 0), &image, 90).unwrap();
        let sky = GrayImage::from_fn(64, 48, |_, y| image::Luma([if y < 20 { 255 } else { 0 }]));
        images::write_png_gray(&layout.sky_mask(t, 0), &sky).unwrap();
    }
    layout
}

fn expect_error_naming(root: &Path, file: &Path, needle: &str) -> DataError {
    let error = read_export(root, &ExportOptions::default()).expect_err("the export is malformed");
    let message = error.to_string();
    assert!(message.contains(&file.display().to_string()), "{message:?} should name {}", file.display());
    assert!(message.contains(needle), "{message:?} should say {needle:?}");
    error
}

#[test]
fn a_valid_export_reads_and_prepares() {
    let dir = tempfile::tempdir().unwrap();
    write_minimal_export(dir.path());
    let scene = read_export(dir.path(), &ExportOptions::default()).unwrap();
    assert_eq!((scene.frames.len(), scene.cameras.len()), (2, 1));
    // The mount is identity in Waymo axes: the optical axis is the ego's forward axis.
    let axis = scene.view(1, 0).world_from_camera.transform_vector(dggt_geom::glam::DVec3::Z);
    assert!(axis.abs_diff_eq(dggt_geom::glam::DVec3::X, 1e-12));
    assert!((scene.trajectory_length(0) - 1.0).abs() < 1e-12);
    let view =
        prepare_view(&scene, 1, 0, &Preprocess { target_width: 56, patch_size: 14, crop_to_square: true }).unwrap();
    assert_eq!((view.image.size.width, view.image.size.height), (56, 42));
    let sky = view.sky_mask.unwrap();
    assert!((sky.coverage() - 17.0 / 42.0).abs() < 0.03, "{}", sky.coverage());
}

#[test]
fn a_view_the_cache_keeps_is_the_view_decoded_and_a_file_broken_later_is_not_reread() {
    let dir = tempfile::tempdir().unwrap();
    write_minimal_export(dir.path());
    let scene = read_export(dir.path(), &ExportOptions::default()).unwrap();
    let preprocess = Preprocess { target_width: 56, patch_size: 14, crop_to_square: true };
    let cache = DecodedViews::new(1 << 20);
    let decoded = prepare_view(&scene, 1, 0, &preprocess).unwrap();
    let first = prepare_view_cached(&scene, 1, 0, &preprocess, &cache).unwrap();
    assert!(cache.bytes() > 0, "the image and the sky mask are kept");
    // Kept views come from memory: the files are not read again.
    std::fs::write(&scene.view(1, 0).files.image, b"no longer a JPEG").unwrap();
    let second = prepare_view_cached(&scene, 1, 0, &preprocess, &cache).unwrap();
    for view in [&first, &second] {
        assert_eq!(view.image, decoded.image);
        assert_eq!(view.sky_mask, decoded.sky_mask);
        assert_eq!(view.dynamic_mask, decoded.dynamic_mask);
    }
    // Without the cache the broken file is an error naming it.
    let error = prepare_view(&scene, 1, 0, &preprocess).unwrap_err().to_string();
    assert!(error.contains(&scene.view(1, 0).files.image.display().to_string()), "{error}");
}

#[test]
fn non_finite_pose() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.ego_pose(1), "1 0 0 NaN\n0 1 0 0\n0 0 1 0\n0 0 0 1\n").unwrap();
    expect_error_naming(dir.path(), &layout.ego_pose(1), "finite");
}

#[test]
fn non_rigid_extrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.extrinsics(0), "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n").unwrap();
    expect_error_naming(dir.path(), &layout.extrinsics(0), "not a rigid transform");
}

#[test]
fn wrong_number_of_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.intrinsics(0), "50\n50\n32\n24\n").unwrap();
    expect_error_naming(dir.path(), &layout.intrinsics(0), "9 numbers");
}

#[test]
fn unparsable_matrix() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.ego_pose(0), "1 0 0 0\n0 1 0 zero\n0 0 1 0\n0 0 0 1\n").unwrap();
    expect_error_naming(dir.path(), &layout.ego_pose(0), "\"zero\"");
}

#[test]
fn corrupt_image() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.image(1, 0), b"definitely not a jpeg").unwrap();
    expect_error_naming(dir.path(), &layout.image(1, 0), "image");
}

#[test]
fn image_size_disagrees_with_the_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    images::write_jpeg(&layout.image(1, 0), &RgbImage::new(32, 48), 90).unwrap();
    expect_error_naming(dir.path(), &layout.image(1, 0), "64x48");
    // The first image defines the size; a principal point outside it is caught against the intrinsics.
    images::write_jpeg(&layout.image(0, 0), &RgbImage::new(20, 20), 90).unwrap();
    expect_error_naming(dir.path(), &layout.intrinsics(0), "principal point");
}

#[test]
fn missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::remove_file(layout.sky_mask(1, 0)).unwrap();
    expect_error_naming(dir.path(), &layout.sky_mask(1, 0), "missing");
    std::fs::remove_file(layout.intrinsics(0)).unwrap();
    expect_error_naming(dir.path(), &dir.path().join("intrinsics"), "none");
    let error = read_export(&dir.path().join("nope"), &ExportOptions::default()).unwrap_err();
    assert!(error.to_string().contains("nope"));
}

#[test]
fn frame_and_camera_selection() {
    let dir = tempfile::tempdir().unwrap();
    write_minimal_export(dir.path());
    let options = ExportOptions { cameras: Some(vec![0]), frames: Some(1..2), ..ExportOptions::default() };
    let scene = read_export(dir.path(), &options).unwrap();
    assert_eq!(scene.frames[0].index, 1);
    let centre = scene.view(0, 0).world_from_camera.translation();
    assert!((centre.x - 1.5).abs() < 1e-12, "world anchored at the ego of the first chosen frame: {centre}");
    let past = ExportOptions { frames: Some(0..1000), ..ExportOptions::default() };
    let message = read_export(dir.path(), &past).unwrap_err().to_string();
    assert!(message.contains("window 0..1000") && message.contains("the scene's 2 frames (0..=1)"), "{message}");
    assert!(!message.contains("ego_pose"), "{message}");
}

#[test]
fn corrupt_mask_is_reported_when_prepared() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    std::fs::write(layout.sky_mask(0, 0), [0x89, b'P', b'N', b'G', 0, 0]).unwrap();
    let scene = read_export(dir.path(), &ExportOptions::default()).unwrap();
    let message = prepare_view(&scene, 0, 0, &Preprocess::default()).unwrap_err().to_string();
    assert!(message.contains("000_0.png"), "{message}");
}

#[test]
fn the_scene_flow_says_where_it_comes_from() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    let origin = || read_export(dir.path(), &ExportOptions::default()).unwrap().flow_origin();
    assert_eq!(origin().unwrap(), FlowOrigin::Absent, "no maps, no flow");

    // Maps of 64x48 images: a 12x16 grid of depth and flow.
    for t in 0..2 {
        npy::write_npy_f32(&layout.depth_flow(t, 0), &[12, 16, 4], &vec![0.0; 12 * 16 * 4]).unwrap();
    }
    assert_eq!(origin().unwrap(), FlowOrigin::Export, "maps without a record came with the export");

    write_flow_origin(&layout, FlowOrigin::TrackedBoxes).unwrap();
    assert_eq!(origin().unwrap(), FlowOrigin::TrackedBoxes);

    let record = layout.depth_flow_origin();
    std::fs::write(&record, br#"{"scene_flow": "guessed"}"#).unwrap();
    let message = origin().expect_err("an unknown origin").to_string();
    assert!(message.contains(&record.display().to_string()) && message.contains("guessed"), "{message}");
}

/// STORM's maps (no origin record: [`FlowOrigin::Export`]) carry the flow along the vehicle's axes of their frame;
/// the scene gives it along the log world's. Frame 1's ego is turned a quarter turn about up, so its forward
/// (x) is the log's left (y); the converters' maps (a record) are read as written.
#[test]
fn storm_maps_flow_is_turned_from_the_vehicle_axes() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write_minimal_export(dir.path());
    let turned = [[0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
    text::write_rows(&layout.ego_pose(1), &turned).unwrap();
    let mut cells = vec![0.0f32; 12 * 16 * 4];
    cells[..4].copy_from_slice(&[5.0, 2.0, 0.5, -0.25]);
    for t in 0..2 {
        npy::write_npy_f32(&layout.depth_flow(t, 0), &[12, 16, 4], &cells).unwrap();
    }
    let first_flow = |frame: usize| {
        let scene = read_export(dir.path(), &ExportOptions::default()).unwrap();
        let map = scene.depth_map(frame, 0).unwrap().expect("a map");
        assert_eq!(map.depth[0], 5.0);
        map.flow.expect("flow")[0]
    };
    let close = |found: [f32; 3], expected: [f32; 3]| found.iter().zip(expected).all(|(f, e)| (f - e).abs() < 1e-6);
    assert!(close(first_flow(0), [2.0, 0.5, -0.25]), "frame 0's vehicle has the log's axes: {:?}", first_flow(0));
    assert!(close(first_flow(1), [-0.5, 2.0, -0.25]), "forward is the log's left: {:?}", first_flow(1));

    write_flow_origin(&layout, FlowOrigin::TrackedBoxes).unwrap();
    assert!(close(first_flow(1), [2.0, 0.5, -0.25]), "the converters' maps are in the log's axes already");
}
