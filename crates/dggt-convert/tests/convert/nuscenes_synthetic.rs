//! The nuScenes converter on a tiny scene whose devkit tables, JPEGs and lidar sweep the test writes itself: two
//! samples, six 80 x 60 cameras, LIDAR_TOP, one annotated car. The written matrices are checked against ones
//! computed here from the raw quaternions (w, x, y, z) and translations, lidar points land where they were put,
//! the car's mask covers its projected box, and bad tables fail naming the table, row or file.

use std::path::Path;

use dggt_convert::depth_flows::DepthFlows;
use dggt_convert::masks::DynamicMaskStyle;
use dggt_convert::nuscenes::{FrameRate, NuScenesOptions, NuScenesVersion, Tables, convert_scene};
use dggt_convert::sky::SkyMasks;
use dggt_data::{DynamicMaskKind, ExportLayout, text};
use dggt_geom::glam::{DMat4, DVec3};
use serde_json::{Value, json};

use crate::nuscenes_scene::*;

fn convert(root: &Path, out: &Path, cameras: &[usize]) -> Result<usize, String> {
    convert_at(root, out, cameras, FrameRate::KeyFrames)
}

fn convert_at(root: &Path, out: &Path, cameras: &[usize], rate: FrameRate) -> Result<usize, String> {
    convert_with(root, out, cameras, rate, DynamicMaskStyle::Drivestudio)
}

fn convert_with(
    root: &Path,
    out: &Path,
    cameras: &[usize],
    rate: FrameRate,
    dynamic_masks: DynamicMaskStyle,
) -> Result<usize, String> {
    let tables = Tables::read(root, &NuScenesVersion::Mini).map_err(|e| e.to_string())?;
    let options = NuScenesOptions {
        cameras: cameras.to_vec(),
        sky_masks: SkyMasks::Lidar,
        depth_flows: DepthFlows::FromBoxes,
        dynamic_masks,
        rate,
    };
    convert_scene(&tables, 0, out, &options, &|_| {}).map(|s| s.frames).map_err(|e| e.to_string())
}

fn read_matrix(path: &Path) -> DMat4 {
    let rows = text::read_matrix::<4, 4>(path).unwrap();
    DMat4::from_cols_array_2d(&rows).transpose()
}

fn assert_close(a: DMat4, b: DMat4, what: &str) {
    assert!(a.abs_diff_eq(b, 1e-9), "{what}:\n{a}\n!=\n{b}");
}

#[test]
fn a_synthetic_scene_converts_to_the_hand_computed_poses_points_and_masks() {
    let dir = tempfile::tempdir().unwrap();
    let root = write_root(dir.path(), |_| {});
    let out = dir.path().join("000");
    assert_eq!(convert(&root, &out, &[0, 1, 2, 3, 4, 5]), Ok(2));
    let layout = ExportLayout::new(&out);

    // CAM_FRONT at sample 0, by hand: the ego faces world +y, so camera z (forward) -> world +y, x (right) ->
    // world +x, y (down) -> world -z; the mounting (1.5, 0, 1.5) turned to world is (0, 1.5, 1.5).
    let by_hand = DMat4::from_cols_array_2d(&[
        [1.0, 0.0, 0.0, 100.0],
        [0.0, 0.0, 1.0, 201.5],
        [0.0, -1.0, 0.0, 1.5],
        [0.0, 0.0, 0.0, 1.0],
    ])
    .transpose();
    assert_close(read_matrix(&layout.extrinsics_at(0, 0)), by_hand, "CAM_FRONT camera -> world");
    for s in 0..2 {
        for c in 0..6 {
            let expected = world_from(ego_pose(s, c)) * world_from(camera_calibration(c));
            assert_close(read_matrix(&layout.extrinsics_at(s, c)), expected, &format!("camera {c} at {s}"));
        }
        let lidar = world_from(ego_pose(s, 6)) * world_from(lidar_calibration());
        assert_close(read_matrix(&layout.lidar_pose(s)), lidar, &format!("lidar pose {s}"));
    }
    let intrinsics = text::read_numbers(&layout.intrinsics(3), 9).unwrap();
    assert_eq!(intrinsics, vec![FX, FX, CX, CY, 0.0, 0.0, 0.0, 0.0, 0.0]);

    // The lidar rows are x y z intensity in the lidar frame; through the written poses the first lands on the
    // target pixel.
    let bytes = std::fs::read(layout.lidar(0)).unwrap();
    let values: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    assert_eq!(values.len(), 16);
    assert_eq!(values[3], 7.0);
    let point = DVec3::new(values[0].into(), values[1].into(), values[2].into());
    let world = read_matrix(&layout.lidar_pose(0)).transform_point3(point);
    let camera = read_matrix(&layout.extrinsics_at(0, 0)).inverse().transform_point3(world);
    let pixel = (FX * camera.x / camera.z + CX, FX * camera.y / camera.z + CY);
    assert!((pixel.0 - TARGET_PIXEL.0).abs() < 1e-4 && (pixel.1 - TARGET_PIXEL.1).abs() < 1e-4, "{pixel:?}");

    // The car, 12 m ahead of CAM_FRONT's ego: its corners at depths 8.5 .. 12.5 span u 34.1 .. 45.9 and
    // v 28.5 .. 37.4 (the camera is 0.5 m above the box centre); the mask fills that rectangle by the rule.
    let mask = image::open(layout.dynamic_mask(DynamicMaskKind::Vehicle, 0, 0)).unwrap().to_luma8();
    let set: Vec<(u32, u32)> = mask.enumerate_pixels().filter(|p| p.2.0[0] == 255).map(|p| (p.0, p.1)).collect();
    let (u0, u1) = (CX - FX / 8.5, CX + FX / 8.5);
    let (v0, v1) = (CY + FX * -0.25 / 8.5, CY + FX * 1.25 / 8.5);
    let cols = u0 as u32..u0 as u32 + (u1 - u0) as u32;
    let rows = v0 as u32..v0 as u32 + (v1 - v0) as u32;
    let expected: Vec<(u32, u32)> = rows.flat_map(|r| cols.clone().map(move |c| (c, r))).collect();
    let mut sorted = set;
    sorted.sort_by_key(|&(c, r)| (r, c));
    assert_eq!(sorted, expected);
    let all = image::open(layout.dynamic_mask(DynamicMaskKind::All, 0, 0)).unwrap().to_luma8();
    assert_eq!(all, mask);
    let human = image::open(layout.dynamic_mask(DynamicMaskKind::Human, 0, 0)).unwrap().to_luma8();
    assert!(human.pixels().all(|p| p.0[0] == 0));
    let behind = image::open(layout.dynamic_mask(DynamicMaskKind::Vehicle, 0, 5)).unwrap().to_luma8();
    assert!(behind.pixels().all(|p| p.0[0] == 0), "CAM_BACK does not see the car");

    // Approximate sky: above the target point's row (25, less a 2-row margin) in its column.
    let sky = image::open(layout.sky_mask(0, 0)).unwrap().to_luma8();
    assert_eq!(sky.get_pixel(20, 0).0[0], 255);
    assert_eq!(sky.get_pixel(20, 22).0[0], 255);
    assert_eq!(sky.get_pixel(20, 23).0[0], 0);
    assert_eq!(sky.get_pixel(70, 0).0[0], 0, "no return in that column");
    assert!(std::fs::read_to_string(out.join("sky_masks/SOURCE.txt")).unwrap().contains("Approximate"));

    // instances/: the car with its global pose and l, w, h; the cone category is not kept.
    let info: Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    assert_eq!(info["0"]["id"], "inst-car");
    assert_eq!(info["0"]["frame_annotations"]["box_size"][1], json!([4.0, 2.0, 1.5]));
    let rows: [[f64; 4]; 4] =
        serde_json::from_value(info["0"]["frame_annotations"]["obj_to_world"][1].clone()).unwrap();
    assert_close(DMat4::from_cols_array_2d(&rows).transpose(), world_from(car_pose(1)), "car box -> world");
    let times = std::fs::read_to_string(layout.timestamps()).unwrap();
    assert_eq!(text::parse_numbers(Path::new("t"), &times).unwrap(), vec![0.0, 0.0, 1.0, 0.5]);

    let marker = dggt_convert::read_done(&out).unwrap();
    assert_eq!((marker.frames, marker.lidar_frames, marker.instances), (2, 2, 1));
    assert!(marker.converter.contains("scene-0061, singapore-onenorth, 2 Hz key frames"), "{}", marker.converter);

    // The export reads back as a nuScenes scene.
    let scene = dggt_data::read_export(&out, &Default::default()).unwrap();
    assert_eq!((scene.frames.len(), scene.cameras.len(), scene.views.len()), (2, 6, 12));
    assert!(scene.views.iter().all(|v| v.files.sky_mask.is_some()));
    assert_front_depth_flows(&out, 2);
}

/// CAM_FRONT's depth-flow maps, read by the loader: the point on the car moves with it, every other return is
/// static.
#[test]
fn a_moving_car_is_masked_by_its_outline_and_a_slow_one_not_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let root = write_root(dir.path(), |_| {});
    // The car keeps 12 m ahead of an ego driving at 10 m/s: it moves.
    let moving = DynamicMaskStyle::MovingOutlines { min_speed_m_s: 0.5 };
    let out = dir.path().join("moving");
    convert_with(&root, &out, &[0, 5], FrameRate::KeyFrames, moving).unwrap();
    let layout = ExportLayout::new(&out);
    let mask = image::open(layout.dynamic_mask(DynamicMaskKind::Vehicle, 0, 0)).unwrap().to_luma8();
    // Seen from straight behind, the outline is the near face (the far one lies inside it): every pixel whose
    // centre is inside u 34.1 .. 45.9, v 28.5 .. 37.4.
    let (u0, u1) = (CX - FX / 8.5, CX + FX / 8.5);
    let (v0, v1) = (CY + FX * -0.25 / 8.5, CY + FX * 1.25 / 8.5);
    for (col, row, value) in mask.enumerate_pixels() {
        let (u, v) = (col as f64 + 0.5, row as f64 + 0.5);
        let inside = (u0..=u1).contains(&u) && (v0..=v1).contains(&v);
        assert_eq!(value.0[0] == 255, inside, "pixel ({col}, {row})");
    }
    let note = std::fs::read_to_string(out.join("dynamic_masks/SOURCE.txt")).unwrap();
    assert!(note.contains("moving-outlines (> 0.5 m/s)"), "{note}");

    // Above 20 m/s nothing this car does counts as moving.
    let out = dir.path().join("fast-only");
    let fast_only = DynamicMaskStyle::MovingOutlines { min_speed_m_s: 20.0 };
    convert_with(&root, &out, &[0], FrameRate::KeyFrames, fast_only).unwrap();
    let mask = image::open(ExportLayout::new(&out).dynamic_mask(DynamicMaskKind::All, 1, 0)).unwrap();
    assert!(mask.to_luma8().pixels().all(|p| p.0[0] == 0));
}

fn assert_front_depth_flows(out: &Path, frames: usize) {
    let scene = dggt_data::read_export(out, &Default::default()).unwrap();
    assert_eq!(
        scene.depth_source(),
        Some(dggt_data::DepthSource::DepthFlows4),
        "depth from the four-channel depth-flow maps"
    );
    assert_eq!(
        scene.flow_origin().unwrap(),
        dggt_data::FlowOrigin::TrackedBoxes,
        "the maps say where their flow is from"
    );
    let front = scene.cameras.iter().position(|c| c.id == 0).unwrap();
    for frame in 0..frames {
        let map = scene.depth_map(frame, front).unwrap().unwrap();
        assert_eq!((map.size.width, map.size.height), (20, 15), "depth maps of the 20 x 15 camera size");
        let flow = map.flow.as_ref().unwrap();
        // The car point is 10.5 m ahead of CAM_FRONT (the car 12 m ahead of the ego, the camera 1.5 m forward),
        // 0.3 m to its right and 0.5 m below it: pixel (40 + 50 · 0.3 / 10.5, 30 + 50 · 0.5 / 10.5) =
        // (41.43, 32.38), cell (row 8, column 10).
        let car = 8 * 20 + 10;
        assert!((map.depth[car] - 10.5).abs() < 1e-4, "frame {frame}: {}", map.depth[car]);
        // The car moves 5 m along world +y per 0.5 s sample: 10 m/s, in the global frame's axes.
        let expected = [0.0, CAR_SPEED as f32, 0.0];
        assert!(flow[car].iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-3), "frame {frame}: {:?}", flow[car]);
        let moving: Vec<usize> = (0..flow.len()).filter(|&i| flow[i] != [0.0; 3]).collect();
        assert_eq!(moving, vec![car], "frame {frame}: only the car point moves");
    }
    let target = 6 * 20 + 5;
    let first = scene.depth_map(0, front).unwrap().unwrap();
    assert!((first.depth[target] - TARGET_PIXEL.2 as f32).abs() < 1e-4, "the static target point's depth");
}

#[test]
fn interpolated_frames_take_the_nearest_readings_and_interpolated_boxes() {
    let dir = tempfile::tempdir().unwrap();
    let root = write_root(dir.path(), |_| {});
    let out = dir.path().join("000");
    // 4 Hz: one frame between the two key frames, at 1.25 s, where the non-key-frame readings are.
    assert_eq!(convert_at(&root, &out, &[0, 5], FrameRate::Interpolated { between: 1 }), Ok(3));
    let layout = ExportLayout::new(&out);
    let times = std::fs::read_to_string(layout.timestamps()).unwrap();
    assert_eq!(text::parse_numbers(Path::new("t"), &times).unwrap(), vec![0.0, 0.0, 1.0, 0.25, 2.0, 0.5]);
    for (frame, position) in [(0, 0.0), (1, 0.5), (2, 1.0)] {
        let camera = world_from(ego_pose_at(position, 5)) * world_from(camera_calibration(5));
        assert_close(read_matrix(&layout.extrinsics_at(frame, 5)), camera, &format!("CAM_BACK at frame {frame}"));
        let lidar = world_from(ego_pose_at(position, 6)) * world_from(lidar_calibration());
        assert_close(read_matrix(&layout.lidar_pose(frame)), lidar, &format!("lidar at frame {frame}"));
    }
    // The car's box halfway between its two annotations (same heading: the translation's midpoint).
    let info: Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    assert_eq!(info["0"]["frame_annotations"]["frame_idx"], json!([0, 1, 2]));
    let rows: [[f64; 4]; 4] =
        serde_json::from_value(info["0"]["frame_annotations"]["obj_to_world"][1].clone()).unwrap();
    let (a, b) = (car_pose(0), car_pose(1));
    let midpoint = DVec3::from_array(a.1).lerp(DVec3::from_array(b.1), 0.5).to_array();
    assert_close(DMat4::from_cols_array_2d(&rows).transpose(), world_from((a.0, midpoint)), "car at frame 1");
    let scene = dggt_data::read_export(&out, &Default::default()).unwrap();
    assert_eq!((scene.frames.len(), scene.views.len()), (3, 6));
    // The interpolated frame's box moves as the key frames' do: 10 m/s at every frame.
    assert_front_depth_flows(&out, 3);
}

fn error_of(edit: impl FnOnce(&mut Vec<(&'static str, Value)>), cameras: &[usize]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let root = write_root(dir.path(), edit);
    convert(&root, &dir.path().join("000"), cameras).unwrap_err()
}

fn rows<'a>(tables: &'a mut [(&'static str, Value)], name: &str) -> &'a mut Vec<Value> {
    tables.iter_mut().find(|(n, _)| *n == name).unwrap().1.as_array_mut().unwrap()
}

#[test]
fn bad_tables_fail_naming_the_table_row_or_file() {
    // Rows: s0 sensors 0..7, then the in-between readings, then s1.
    let missing_file = {
        let dir = tempfile::tempdir().unwrap();
        let root = write_root(dir.path(), |_| {});
        std::fs::remove_file(root.join("samples/CAM_BACK/log__CAM_BACK__1500000.jpg")).unwrap();
        convert(&root, &dir.path().join("000"), &[5]).unwrap_err()
    };
    assert!(
        missing_file.contains("log__CAM_BACK__1500000.jpg") && missing_file.contains("data-s1-5"),
        "{missing_file}"
    );

    let no_calibration = error_of(|t| rows(t, "sample_data")[3]["calibrated_sensor_token"] = json!("cal-gone"), &[0]);
    assert!(
        no_calibration.contains("calibrated_sensor.json")
            && no_calibration.contains("cal-gone")
            && no_calibration.contains("data-s0-3"),
        "{no_calibration}"
    );

    let no_intrinsics = error_of(|t| rows(t, "calibrated_sensor")[1]["camera_intrinsic"] = json!([]), &[0]);
    assert!(
        no_intrinsics.contains("calibrated_sensor.json")
            && no_intrinsics.contains("cal-0")
            && no_intrinsics.contains("3x3"),
        "{no_intrinsics}"
    );

    let no_log = error_of(|t| rows(t, "log")[0]["token"] = json!("log-other"), &[0]);
    assert!(no_log.contains("log.json") && no_log.contains("log-0") && no_log.contains("scene `scene-0`"), "{no_log}");

    let unknown_camera = error_of(|_| {}, &[6]);
    assert!(unknown_camera.contains("camera 6") && unknown_camera.contains("CAM_BACK"), "{unknown_camera}");

    let non_rigid = error_of(|t| rows(t, "ego_pose")[2]["rotation"] = json!([2.0, 0.0, 0.0, 0.0]), &[0, 1, 2]);
    assert!(
        non_rigid.contains("ego_pose.json") && non_rigid.contains("pose-s0-2") && non_rigid.contains("norm 2"),
        "{non_rigid}"
    );

    let not_a_number = error_of(|t| rows(t, "sample_annotation")[0]["rotation"] = json!([null, 0.0, 0.0, 1.0]), &[0]);
    assert!(not_a_number.contains("sample_annotation.json") && not_a_number.contains("rows"), "{not_a_number}");

    let cut_sweep = {
        let dir = tempfile::tempdir().unwrap();
        let root = write_root(dir.path(), |_| {});
        std::fs::write(root.join("samples/LIDAR_TOP/log__LIDAR_TOP__1000000.pcd.bin"), [0u8; 30]).unwrap();
        convert(&root, &dir.path().join("000"), &[0]).unwrap_err()
    };
    assert!(cut_sweep.contains("LIDAR_TOP__1000000.pcd.bin") && cut_sweep.contains("30 bytes"), "{cut_sweep}");
}
