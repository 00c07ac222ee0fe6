//! The Waymo converter on real records: a frame with five camera images and 75 laser labels, and a frame
//! stripped of its images. The data lives beside the repository (`../shared/real-data`, or `$DGGT_REAL_DATA`);
//! it is licensed for non-commercial research and never copied into the repository.

use std::path::{Path, PathBuf};

use dggt_convert::camera::{Distortion, EgoCamera};
use dggt_convert::waymo::{WaymoOptions, convert_segment, proto};
use dggt_convert::{DONE_MARKER, read_done};
use dggt_data::{DynamicMaskKind, ExportLayout, ExportVariant, text};
use dggt_geom::glam::{DVec2, DVec3};
use dggt_geom::{Ego, ImageSize, PinholeIntrinsics, Rigid, WaymoCamera};

use crate::common::real_data;

fn one_frame() -> PathBuf {
    real_data().join("waymo/one_frame_5cams.tfrecord")
}

fn convert(input: &Path, scene: &Path) -> dggt_convert::Result<dggt_convert::waymo::SegmentSummary> {
    convert_segment(input, scene, &WaymoOptions::default(), &|_| {})
}

/// The first record's frame, decoded independently of the converter's streaming reader.
fn first_frame(path: &Path) -> proto::Frame {
    let bytes = std::fs::read(path).unwrap();
    let length = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    proto::decode_frame(&bytes[12..12 + length]).unwrap()
}

fn max_difference(ours: &Path, reference: &Path, count: usize) -> f64 {
    let (a, b) = (text::read_numbers(ours, count).unwrap(), text::read_numbers(reference, count).unwrap());
    a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn one_frame_converts_to_the_reference_export() {
    let out = tempfile::tempdir().unwrap();
    let scene = out.path().join("000");
    let summary = convert(&one_frame(), &scene).unwrap();
    assert_eq!((summary.frames, summary.images, summary.lidar_frames), (1, 5, 0));
    let ours = ExportLayout::new(&scene);
    let reference = ExportLayout::new(real_data().join("waymo/export_one_frame/000"));
    let mut worst = 0.0f64;
    for camera in 0..5 {
        worst = worst.max(max_difference(&ours.intrinsics(camera), &reference.intrinsics(camera), 9));
        worst = worst.max(max_difference(&ours.extrinsics(camera), &reference.extrinsics(camera), 16));
        let (a, b) =
            (std::fs::read(ours.image(0, camera)).unwrap(), std::fs::read(reference.image(0, camera)).unwrap());
        assert!(a == b, "camera {camera}: JPEG bytes differ ({} vs {} bytes)", a.len(), b.len());
    }
    worst = worst.max(max_difference(&ours.ego_pose(0), &reference.ego_pose(0), 16));
    println!("largest difference of intrinsics, extrinsics and ego pose from the reference export: {worst:e}");
    assert!(worst <= 1e-9, "{worst}");
    assert_eq!(ExportVariant::detect(&scene).unwrap(), ExportVariant::Waymo);
    let read = dggt_data::read_export(&scene, &Default::default()).unwrap();
    assert_eq!((read.cameras.len(), read.frames.len()), (5, 1));
    assert_eq!(read_done(&scene).unwrap().frames, 1);
}

#[test]
fn labels_become_instances_and_masks_of_the_calibrated_size() {
    let out = tempfile::tempdir().unwrap();
    let scene = out.path().join("000");
    convert(&one_frame(), &scene).unwrap();
    let frame = first_frame(&one_frame());
    assert_eq!(frame.laser_labels.len(), 75);
    let kept: Vec<&proto::Label> = frame.laser_labels.iter().filter(|l| matches!(l.r#type, Some(1 | 2 | 4))).collect();
    let layout = ExportLayout::new(&scene);
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    let info = info.as_object().unwrap();
    assert_eq!(info.len(), kept.len(), "one instance per vehicle, pedestrian and cyclist label");
    let first = &info["0"];
    assert_eq!(first["id"], kept[0].id.as_deref().unwrap());
    let obj_to_world = &first["frame_annotations"]["obj_to_world"][0];
    let pose: Vec<f64> = frame.pose.as_ref().unwrap().transform.clone();
    let b = kept[0].r#box.as_ref().unwrap();
    let (c, s) = (b.heading.unwrap().cos(), b.heading.unwrap().sin());
    let local = [b.center_x.unwrap(), b.center_y.unwrap(), b.center_z.unwrap()];
    for row in 0..3 {
        let expected = (0..3).map(|k| pose[row * 4 + k] * local[k]).sum::<f64>() + pose[row * 4 + 3];
        let written = obj_to_world[row][3].as_f64().unwrap();
        assert!((written - expected).abs() < 1e-6, "centre row {row}: {written} vs {expected}");
        // The box's x axis in the world is the pose's rotation applied to (cos heading, sin heading, 0).
        let axis = pose[row * 4] * c + pose[row * 4 + 1] * s;
        assert!((obj_to_world[row][0].as_f64().unwrap() - axis).abs() < 1e-9);
    }
    let frame_instances: serde_json::Value =
        serde_json::from_slice(&std::fs::read(layout.frame_instances()).unwrap()).unwrap();
    assert_eq!(frame_instances["0"].as_array().unwrap().len(), kept.len());

    let moving = kept.iter().filter(|l| {
        let m = l.metadata.as_ref().unwrap();
        m.speed_x.unwrap_or(0.0).hypot(m.speed_y.unwrap_or(0.0)) > 1.0
    });
    println!("{} labels, {} kept, {} moving faster than 1 m/s", frame.laser_labels.len(), kept.len(), moving.count());
    for camera in 0..5 {
        let expected = if camera < 3 { (1920, 1280) } else { (1920, 886) };
        let mut set = [0usize; 3];
        for (slot, kind) in
            [DynamicMaskKind::All, DynamicMaskKind::Human, DynamicMaskKind::Vehicle].into_iter().enumerate()
        {
            let mask = dggt_data::images::read_gray(&layout.dynamic_mask(kind, 0, camera)).unwrap();
            assert_eq!(mask.dimensions(), expected, "camera {camera} {kind:?}");
            assert!(mask.pixels().all(|p| p.0[0] == 0 || p.0[0] == 255));
            set[slot] = mask.pixels().filter(|p| p.0[0] == 255).count();
        }
        println!("camera {camera}: dynamic pixels all {} human {} vehicle {}", set[0], set[1], set[2]);
        assert!(set[0] >= set[1].max(set[2]) && set[0] <= set[1] + set[2], "all is the union of human and vehicle");
    }
}

/// A camera as the export describes it: `intrinsics/{cam}.txt` and `extrinsics/{cam}.txt` (Waymo axes).
fn written_camera(layout: &ExportLayout, camera: usize, size: ImageSize) -> EgoCamera {
    let k = text::read_numbers(&layout.intrinsics(camera), 9).unwrap();
    let ego_from_camera =
        Rigid::<Ego, WaymoCamera>::from_rows(text::read_matrix(&layout.extrinsics(camera)).unwrap()).unwrap();
    EgoCamera {
        intrinsics: PinholeIntrinsics::new(k[0], k[1], k[2], k[3]).unwrap(),
        distortion: Distortion { k1: k[4], k2: k[5], p1: k[6], p2: k[7], k3: k[8] },
        camera_from_ego: dggt_geom::axes::ego_from_opencv_camera(&ego_from_camera).inverse(),
        size,
    }
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// The laser label's box projected with the written camera: its centre, and the centre of the rectangle around
/// its 8 corners (what `projected_lidar_labels` holds, as Waymo's own camera model draws it).
fn projected_centres(model: &EgoCamera, laser: &proto::Label) -> (DVec2, DVec2) {
    let b = laser.r#box.as_ref().unwrap();
    let centre = DVec3::new(b.center_x.unwrap(), b.center_y.unwrap(), b.center_z.unwrap());
    let (c, s) = (b.heading.unwrap().cos(), b.heading.unwrap().sin());
    let half = DVec3::new(b.length.unwrap(), b.width.unwrap(), b.height.unwrap()) * 0.5;
    let (mut min, mut max) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for corner in 0..8 {
        let sign = |bit: usize| if corner & (1 << bit) == 0 { -1.0 } else { 1.0 };
        let local = DVec3::new(sign(0) * half.x, sign(1) * half.y, sign(2) * half.z);
        let offset = DVec3::new(c * local.x - s * local.y, s * local.x + c * local.y, local.z);
        let pixel = model.project(centre + offset).expect("a labelled box in front of the camera");
        (min, max) = (min.min(pixel), max.max(pixel));
    }
    (model.project(centre).unwrap(), (min + max) * 0.5)
}

#[test]
fn box_centres_project_onto_the_frames_projected_labels() {
    let out = tempfile::tempdir().unwrap();
    let scene = out.path().join("000");
    convert(&one_frame(), &scene).unwrap();
    let layout = ExportLayout::new(&scene);
    let frame = first_frame(&one_frame());
    const NAMES: [&str; 5] = ["FRONT", "FRONT_LEFT", "FRONT_RIGHT", "SIDE_LEFT", "SIDE_RIGHT"];
    for projected in &frame.projected_lidar_labels {
        let camera = projected.name.unwrap() as usize - 1;
        let size = if camera < 3 { ImageSize::new(1920, 1280) } else { ImageSize::new(1920, 886) }.unwrap();
        let model = written_camera(&layout, camera, size);
        let (mut centre_distances, mut rectangle_distances) = (Vec::new(), Vec::new());
        for label in &projected.labels {
            let b = label.r#box.as_ref().unwrap();
            let (u, v, w, h) = (b.center_x.unwrap(), b.center_y.unwrap(), b.length.unwrap(), b.width.unwrap());
            // Rectangles clamped at the image border have a shifted centre: only whole ones are compared.
            let (width, height) = (size.width as f64, size.height as f64);
            if u - w / 2.0 < 1.0 || v - h / 2.0 < 1.0 || u + w / 2.0 > width - 1.0 || v + h / 2.0 > height - 1.0 {
                continue;
            }
            let laser_id = label.id.as_deref().unwrap().strip_suffix(&format!("_{}", NAMES[camera])).unwrap();
            let laser = frame.laser_labels.iter().find(|l| l.id.as_deref() == Some(laser_id)).unwrap();
            let (centre, rectangle_centre) = projected_centres(&model, laser);
            centre_distances.push((centre - DVec2::new(u, v)).length());
            rectangle_distances.push((rectangle_centre - DVec2::new(u, v)).length());
        }
        assert!(!centre_distances.is_empty(), "{}: no whole projected label", NAMES[camera]);
        let boxes = centre_distances.len();
        let (centre, rectangle) = (median(centre_distances), median(rectangle_distances));
        println!(
            "{}: over {boxes} boxes, median distance from the projected label's centre: box centre {centre:.2} px, \
             centre of the projected corners' rectangle {rectangle:.2} px",
            NAMES[camera]
        );
        assert!(rectangle < 1.0, "{}: {rectangle}", NAMES[camera]);
        assert!(centre < 10.0, "{}: {centre}", NAMES[camera]);
    }
}

#[test]
fn a_frame_without_images_converts_its_calibration_and_pose() {
    let input = real_data().join("waymo/stripped_frame_no_images.tfrecord");
    let out = tempfile::tempdir().unwrap();
    let scene = out.path().join("000");
    let summary = convert(&input, &scene).unwrap();
    assert_eq!((summary.frames, summary.images), (1, 0));
    let frame = first_frame(&input);
    assert_eq!(frame.laser_labels.len(), 18);
    let layout = ExportLayout::new(&scene);
    let pose = text::read_numbers(&layout.ego_pose(0), 16).unwrap();
    assert_eq!(pose, frame.pose.as_ref().unwrap().transform);
    for calibration in &frame.context.as_ref().unwrap().camera_calibrations {
        let camera = calibration.name.unwrap() as usize - 1;
        assert_eq!(text::read_numbers(&layout.intrinsics(camera), 9).unwrap(), calibration.intrinsic);
        assert_eq!(
            text::read_numbers(&layout.extrinsics(camera), 16).unwrap(),
            calibration.extrinsic.as_ref().unwrap().transform
        );
    }
    assert!(!layout.image(0, 0).exists());
    assert!(scene.join(DONE_MARKER).is_file());
}

#[test]
fn damaged_copies_fail_naming_the_file_and_the_record() {
    let good = std::fs::read(one_frame()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let flipped_path = dir.path().join("flipped.tfrecord");
    let mut flipped = good.clone();
    flipped[12 + 1000] ^= 0x20;
    std::fs::write(&flipped_path, &flipped).unwrap();
    let truncated_path = dir.path().join("truncated.tfrecord");
    std::fs::write(&truncated_path, &good[..good.len() / 2]).unwrap();
    for (path, what) in [(&flipped_path, "payload CRC"), (&truncated_path, "truncated record")] {
        let scene = dir.path().join("scene");
        let message = convert(path, &scene).unwrap_err().to_string();
        println!("{message}");
        assert!(message.contains(&path.display().to_string()) && message.contains("record 0"), "{message}");
        assert!(message.contains(what), "{message}");
        assert!(read_done(&scene).is_none(), "a failed segment is not marked done");
    }
}
