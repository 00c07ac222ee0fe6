//! Range images to lidar rows on a record built here (the public records carry empty range images): a TOP lidar
//! with uniform beams, with and without per-pixel poses, and a flow image.

use std::f64::consts::PI;
use std::io::Write;

use dggt_convert::tfrecord::frame_record;
use dggt_convert::waymo::{WaymoOptions, convert_segment, proto};
use dggt_data::ExportLayout;
use flate2::write::ZlibEncoder;
use prost::Message;

const HEIGHT: usize = 2;
const WIDTH: usize = 4;
/// Lidar mounted 1 m forward and 2 m up, turned 90° left (its x axis is the vehicle's y).
const LIDAR_TO_VEHICLE: [f64; 16] = [0.0, -1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0];
const IDENTITY: [f64; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

fn compressed(values: Vec<f32>, channels: i32) -> Vec<u8> {
    let matrix = proto::MatrixFloat {
        data: values,
        shape: Some(proto::MatrixShape { dims: vec![HEIGHT as i32, WIDTH as i32, channels] }),
    };
    let mut encoder = ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    encoder.write_all(&matrix.encode_to_vec()).unwrap();
    encoder.finish().unwrap()
}

/// Range `10 + col` m in row 0, no return in row 1 except column 2; intensity `col`, elongation `row`.
fn range_values() -> Vec<f32> {
    let mut values = Vec::new();
    for row in 0..HEIGHT {
        for col in 0..WIDTH {
            let range = if row == 0 || col == 2 { 10.0 + col as f32 } else { 0.0 };
            values.extend([range, col as f32, row as f32, 0.0]);
        }
    }
    values
}

fn frame(pose_image: Option<Vec<f32>>, flow: Option<Vec<f32>>) -> proto::Frame {
    let transform = |values: &[f64]| Some(proto::Transform { transform: values.to_vec() });
    let calibration = proto::CameraCalibration {
        name: Some(1),
        intrinsic: vec![1000.0, 1000.0, 960.0, 640.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        extrinsic: transform(&[1.0, 0.0, 0.0, 1.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0]),
        width: Some(1920),
        height: Some(1280),
    };
    let laser_calibration = proto::LaserCalibration {
        name: Some(1),
        beam_inclinations: vec![],
        beam_inclination_min: Some(-0.2),
        beam_inclination_max: Some(0.2),
        extrinsic: transform(&LIDAR_TO_VEHICLE),
    };
    let range_image = proto::RangeImage {
        range_image_compressed: Some(compressed(range_values(), 4)),
        range_image_pose_compressed: pose_image.map(|values| compressed(values, 6)),
        range_image_flow_compressed: flow.map(|values| compressed(values, 4)),
    };
    proto::Frame {
        context: Some(proto::Context {
            name: Some("built".into()),
            camera_calibrations: vec![calibration],
            laser_calibrations: vec![laser_calibration],
        }),
        timestamp_micros: Some(1_000_000),
        pose: transform(&IDENTITY),
        images: vec![],
        lasers: vec![proto::Laser { name: Some(1), ri_return1: Some(range_image), ri_return2: None }],
        laser_labels: vec![],
        projected_lidar_labels: vec![],
    }
}

fn convert_rows(frame: &proto::Frame) -> Vec<[f32; 14]> {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("built.tfrecord");
    std::fs::write(&input, frame_record(&frame.encode_to_vec())).unwrap();
    let scene = dir.path().join("000");
    let options = WaymoOptions { cameras: vec![0], ..Default::default() };
    let summary = convert_segment(&input, &scene, &options, &|_| {}).unwrap();
    assert_eq!(summary.lidar_frames, 1, "the one frame's lidar written");
    let bytes = std::fs::read(ExportLayout::new(&scene).lidar(0)).unwrap();
    assert_eq!(bytes.len() % (14 * 4), 0, "whole points of 14 f32 values each");
    bytes
        .chunks_exact(14 * 4)
        .map(|row| std::array::from_fn(|i| f32::from_le_bytes(row[i * 4..i * 4 + 4].try_into().unwrap())))
        .collect()
}

/// The expected vehicle-frame point of (row, col) at `range`, worked out from the range-image geometry.
fn expected_point(row: usize, col: usize, range: f64) -> [f64; 3] {
    // Uniform beams from -0.2 to 0.2 rad, row 0 the highest: 0.1, then -0.1.
    let inclination: f64 = if row == 0 { 0.1 } else { -0.1 };
    // The lidar's x axis points along vehicle y: the azimuth offset is atan2(1, 0) = π/2.
    let azimuth = ((WIDTH - col) as f64 - 0.5) / WIDTH as f64 * 2.0 * PI - PI - PI / 2.0;
    let in_lidar = [azimuth.cos() * inclination.cos(), azimuth.sin() * inclination.cos(), f64::sin(inclination)]
        .map(|v| v * range);
    // Vehicle = R · lidar + t with R = [[0,-1,0],[1,0,0],[0,0,1]], t = (1, 0, 2).
    [-in_lidar[1] + 1.0, in_lidar[0], in_lidar[2] + 2.0]
}

#[test]
fn range_images_become_rows_in_the_vehicle_frame() {
    let rows = convert_rows(&frame(None, None));
    assert_eq!(rows.len(), WIDTH + 1, "returns with range > 0 only");
    let cells: Vec<(usize, usize)> = (0..WIDTH).map(|col| (0, col)).chain([(1, 2)]).collect();
    for (row_values, (row, col)) in rows.iter().zip(cells) {
        let expected = expected_point(row, col, 10.0 + col as f64);
        for axis in 0..3 {
            assert!(
                (row_values[3 + axis] as f64 - expected[axis]).abs() < 1e-4,
                "({row}, {col}): {row_values:?} vs {expected:?}"
            );
        }
        assert_eq!(&row_values[..3], &[1.0, 0.0, 2.0], "ray origin is the lidar's position");
        assert_eq!(&row_values[6..10], &[0.0, 0.0, 0.0, -1.0], "no flow image: zero flow, class -1");
        assert_eq!((row_values[11], row_values[12], row_values[13]), (col as f32, row as f32, 0.0));
    }
    // The points' distance from the lidar is their range.
    let p = &rows[1];
    let distance = ((p[3] - 1.0).powi(2) + p[4].powi(2) + (p[5] - 2.0).powi(2)).sqrt();
    assert!((distance - 11.0).abs() < 1e-4);
}

#[test]
fn per_pixel_poses_move_points_into_the_frame_pose_and_flow_is_kept() {
    // Every pixel was taken 0.5 m further along global x and turned 90° (yaw) relative to the frame pose
    // (the identity): the point p becomes Rz(90°) p + (0.5, 0, 0).
    let pose_image: Vec<f32> =
        (0..HEIGHT * WIDTH).flat_map(|_| [0.0, 0.0, std::f32::consts::FRAC_PI_2, 0.5, 0.0, 0.0]).collect();
    let flow: Vec<f32> = (0..HEIGHT * WIDTH).flat_map(|i| [i as f32, 0.5, -0.5, 1.0]).collect();
    let rows = convert_rows(&frame(Some(pose_image), Some(flow)));
    let still = convert_rows(&frame(None, None));
    for (moved, original) in rows.iter().zip(&still) {
        let expected = [-original[4] + 0.5, original[3], original[5]];
        for axis in 0..3 {
            assert!((moved[3 + axis] - expected[axis]).abs() < 1e-4, "{moved:?} vs {expected:?}");
        }
        assert!((moved[0] - 0.5).abs() < 1e-6 && (moved[1] - 1.0).abs() < 1e-6, "the origin moves too: {moved:?}");
        assert_eq!((moved[7], moved[8], moved[9]), (0.5, -0.5, 1.0));
    }
    assert_eq!(rows[4][6], 6.0, "flow of pixel (1, 2), the fifth return");
}

#[test]
fn a_non_rigid_pose_and_an_unknown_camera_are_errors_naming_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let mut sheared = frame(None, None);
    sheared.pose.as_mut().unwrap().transform[1] = 0.5;
    let mut unknown_camera = frame(None, None);
    unknown_camera.images.push(proto::CameraImage { name: Some(7), image: Some(vec![0xFF, 0xD8, 0xFF, 0xD9]) });
    for (frame, expected) in [(sheared, "rigid"), (unknown_camera, "camera name 1..=5")] {
        let input = dir.path().join("bad.tfrecord");
        let good = frame_record(&self::frame(None, None).encode_to_vec());
        std::fs::write(&input, [good, frame_record(&frame.encode_to_vec())].concat()).unwrap();
        let message = convert_segment(
            &input,
            &dir.path().join("000"),
            &WaymoOptions { cameras: vec![0], ..Default::default() },
            &|_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            message.contains("bad.tfrecord") && message.contains("record 1") && message.contains(expected),
            "{message}"
        );
    }
}

#[test]
fn lidar_sky_masks_are_written_per_view_and_mark_no_sky_without_returns_in_view() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("built.tfrecord");
    std::fs::write(&input, frame_record(&frame(None, None).encode_to_vec())).unwrap();
    let scene = dir.path().join("000");
    let options =
        WaymoOptions { cameras: vec![0], sky_masks: dggt_convert::sky::SkyMasks::Lidar, ..Default::default() };
    convert_segment(&input, &scene, &options, &|_| {}).unwrap();
    // The four columns of returns lie at ±45° and ±135° azimuth, outside FRONT's ±43.8° field of view.
    let mask = image::open(ExportLayout::new(&scene).sky_mask(0, 0)).unwrap().to_luma8();
    assert_eq!(mask.dimensions(), (1920, 1280));
    assert!(mask.pixels().all(|p| p.0[0] == 0));
    let note = std::fs::read_to_string(scene.join("sky_masks/SOURCE.txt")).unwrap();
    assert!(note.contains("Approximate"), "{note}");
}

/// A car box around the return of (row 0, column 1), its centre `shift` m further along the vehicle's x.
fn car_label(shift: f64) -> proto::Label {
    let [x, y, z] = expected_point(0, 1, 11.0);
    proto::Label {
        r#box: Some(proto::LabelBox {
            center_x: Some(x + shift),
            center_y: Some(y),
            center_z: Some(z),
            width: Some(2.0),
            length: Some(2.0),
            height: Some(2.0),
            heading: Some(0.0),
        }),
        metadata: None,
        r#type: Some(1),
        id: Some("car".into()),
        num_lidar_points_in_box: Some(1),
        num_top_lidar_points_in_box: None,
    }
}

#[test]
fn depth_flows_give_the_return_inside_a_moving_label_its_velocity() {
    use dggt_convert::depth_flows::DepthFlows;
    use dggt_data::DepthFlowMap;
    use dggt_geom::ImageSize;

    // Two records 0.1 s apart; the car's box moves 0.5 m along x between them: 5 m/s.
    let records: Vec<proto::Frame> = [(0.0, 1_000_000), (0.5, 1_100_000)]
        .into_iter()
        .map(|(shift, time)| {
            let mut record = frame(None, None);
            // The camera at the lidar's position, turned 40° left: of the five returns only (0, 1), at 45° left
            // of the vehicle's x, is in view.
            let (s, c) = 40f64.to_radians().sin_cos();
            let extrinsic = vec![c, -s, 0.0, 1.0, s, c, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0];
            let context = record.context.as_mut().unwrap();
            context.camera_calibrations[0].extrinsic = Some(proto::Transform { transform: extrinsic });
            record.timestamp_micros = Some(time);
            record.laser_labels = vec![car_label(shift)];
            record
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("built.tfrecord");
    let bytes: Vec<u8> = records.iter().flat_map(|r| frame_record(&r.encode_to_vec())).collect();
    std::fs::write(&input, bytes).unwrap();
    let scene = dir.path().join("000");
    let options = WaymoOptions { cameras: vec![0], depth_flows: DepthFlows::FromBoxes, ..Default::default() };
    convert_segment(&input, &scene, &options, &|_| {}).unwrap();
    for frame in 0..2 {
        let path = ExportLayout::new(&scene).depth_flow(frame, 0);
        let map = DepthFlowMap::read(&path, ImageSize::new(1920, 1280).unwrap()).unwrap();
        let filled: Vec<usize> = (0..map.depth.len()).filter(|&i| map.depth[i] > 0.0).collect();
        assert_eq!(filled.len(), 1, "frame {frame}: one return in view");
        let flow = map.flow.as_ref().unwrap();
        // Frame 0 looks ahead, frame 1 (the last) back: both see +0.5 m in 0.1 s along x (the frame pose is the
        // identity, so the log world's axes are the vehicle's).
        let velocity = flow[filled[0]];
        assert!(
            (velocity[0] - 5.0).abs() < 1e-3 && velocity[1].abs() < 1e-4 && velocity[2].abs() < 1e-4,
            "{velocity:?}"
        );
        assert!(flow.iter().enumerate().all(|(i, f)| i == filled[0] || *f == [0.0; 3]));
    }
}

#[test]
fn a_segment_without_lidar_gets_no_depth_flows() {
    use dggt_convert::depth_flows::DepthFlows;

    let mut record = frame(None, None);
    record.lasers.clear();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("built.tfrecord");
    std::fs::write(&input, frame_record(&record.encode_to_vec())).unwrap();
    let scene = dir.path().join("000");
    let options = WaymoOptions { cameras: vec![0], depth_flows: DepthFlows::FromBoxes, ..Default::default() };
    let summary = convert_segment(&input, &scene, &options, &|_| {}).unwrap();
    assert_eq!(summary.lidar_frames, 0);
    assert!(!scene.join("depth_flows_4").exists(), "no lidar, no maps (the reader wants one per view)");
}
