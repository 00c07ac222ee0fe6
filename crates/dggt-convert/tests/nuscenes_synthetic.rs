//! The nuScenes converter on a tiny scene whose devkit tables, JPEGs and lidar sweep the test writes itself: two
//! samples, six 80 x 60 cameras, LIDAR_TOP, one annotated car. The written matrices are checked against ones
//! computed here from the raw quaternions (w, x, y, z) and translations, lidar points land where they were put,
//! the car's mask covers its projected box, and bad tables fail naming the table, row or file.

use std::path::{Path, PathBuf};

use dggt_convert::nuscenes::{NuScenesVersion, Tables, convert_scene};
use dggt_convert::sky::SkyMasks;
use dggt_data::{DynamicMaskKind, ExportLayout, text};
use dggt_geom::glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::{Value, json};

const CHANNELS: [&str; 6] =
    ["CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK_LEFT", "CAM_BACK_RIGHT", "CAM_BACK"];
const YAWS_DEG: [f64; 6] = [0.0, 55.0, -55.0, 110.0, -110.0, 180.0];
const FX: f64 = 50.0;
const CX: f64 = 40.0;
const CY: f64 = 30.0;
const WIDTH: u32 = 80;
const HEIGHT: u32 = 60;
/// The front camera's mounting: x forward, 1.5 m up.
const CAMERA_OFFSET: [f64; 3] = [1.5, 0.0, 1.5];
/// Where the test puts a lidar point: this pixel of CAM_FRONT at sample 0, this far away.
const TARGET_PIXEL: (f64, f64, f64) = (20.5, 25.5, 8.0);

fn wxyz(q: DQuat) -> [f64; 4] {
    [q.w, q.x, q.y, q.z]
}

/// OpenCV camera axes on a forward-left-up ego, turned by `yaw`: camera z forward, x right, y down.
fn ego_from_camera_rotation(yaw: f64) -> DQuat {
    let front = DMat3::from_cols(DVec3::NEG_Y, DVec3::NEG_Z, DVec3::X);
    DQuat::from_rotation_z(yaw) * DQuat::from_mat3(&front)
}

fn matrix(rotation: [f64; 4], translation: [f64; 3]) -> DMat4 {
    let q = DQuat::from_xyzw(rotation[1], rotation[2], rotation[3], rotation[0]);
    DMat4::from_rotation_translation(q, DVec3::from_array(translation))
}

/// The ego pose of every reading: facing world +y (yaw 90°), 5 m further along y per sample, with a small
/// offset per sensor (readings at different times).
fn ego_pose(sample: usize, sensor: usize) -> ([f64; 4], [f64; 3]) {
    let yaw = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
    (wxyz(yaw), [100.0 - 0.1 * sensor as f64, 200.0 + 5.0 * sample as f64, 0.0])
}

fn lidar_calibration() -> ([f64; 4], [f64; 3]) {
    (wxyz(DQuat::from_rotation_z(-std::f64::consts::FRAC_PI_2)), [0.9, 0.0, 1.8])
}

fn camera_calibration(camera: usize) -> ([f64; 4], [f64; 3]) {
    let yaw = YAWS_DEG[camera].to_radians();
    let offset = DQuat::from_rotation_z(yaw) * DVec3::from_array(CAMERA_OFFSET);
    (wxyz(ego_from_camera_rotation(yaw)), offset.to_array())
}

fn world_from(pose: ([f64; 4], [f64; 3])) -> DMat4 {
    matrix(pose.0, pose.1)
}

/// The car: 12 m ahead of the front camera's ego at each sample, 1 m up, heading with the ego; w, l, h = 2, 4, 1.5.
fn car_pose(sample: usize) -> ([f64; 4], [f64; 3]) {
    let pose = ego_pose(sample, 0);
    let centre = world_from(pose).transform_point3(DVec3::new(12.0, 0.0, 1.0));
    (pose.0, centre.to_array())
}

/// The lidar point (in the LIDAR_TOP frame of sample 0) that CAM_FRONT sees at [`TARGET_PIXEL`].
fn target_point_in_lidar() -> DVec3 {
    let (u, v, depth) = TARGET_PIXEL;
    let in_camera = DVec3::new((u - CX) / FX * depth, (v - CY) / FX * depth, depth);
    let world_from_camera = world_from(ego_pose(0, 0)) * world_from(camera_calibration(0));
    let world_from_lidar = world_from(ego_pose(0, 6)) * world_from(lidar_calibration());
    world_from_lidar.inverse().transform_point3(world_from_camera.transform_point3(in_camera))
}

fn write_jpeg(path: &Path, shade: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(WIDTH, HEIGHT, image::Rgb([shade, 100, 50])).save(path).unwrap();
}

fn write_sweep(path: &Path, points: &[[f32; 5]]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
}

/// The tables of the tiny scene, by table name.
fn tables() -> Vec<(&'static str, Value)> {
    let mut sensors = vec![json!({"token": "sensor-lidar", "channel": "LIDAR_TOP", "modality": "lidar"})];
    let (lr, lt) = lidar_calibration();
    let mut calibrated = vec![
        json!({"token": "cal-lidar", "sensor_token": "sensor-lidar", "translation": lt, "rotation": lr, "camera_intrinsic": []}),
    ];
    for (c, channel) in CHANNELS.iter().enumerate() {
        sensors.push(json!({"token": format!("sensor-{c}"), "channel": channel, "modality": "camera"}));
        let (r, t) = camera_calibration(c);
        let k = [[FX, 0.0, CX], [0.0, FX, CY], [0.0, 0.0, 1.0]];
        calibrated.push(json!({"token": format!("cal-{c}"), "sensor_token": format!("sensor-{c}"), "translation": t, "rotation": r, "camera_intrinsic": k}));
    }
    let (mut samples, mut data, mut poses, mut annotations) = (vec![], vec![], vec![], vec![]);
    for s in 0..2 {
        let time = 1_000_000 + 500_000 * s as i64;
        let next = if s == 0 { "sample-1".to_string() } else { String::new() };
        let prev = if s == 1 { "sample-0".to_string() } else { String::new() };
        samples.push(json!({"token": format!("sample-{s}"), "timestamp": time, "scene_token": "scene-0", "next": next, "prev": prev}));
        for sensor in 0..7 {
            let (r, t) = ego_pose(s, sensor);
            let token = format!("s{s}-{sensor}");
            poses.push(json!({"token": format!("pose-{token}"), "translation": t, "rotation": r, "timestamp": time}));
            let (filename, calibration, width, height) = if sensor == 6 {
                (format!("samples/LIDAR_TOP/log__LIDAR_TOP__{time}.pcd.bin"), "cal-lidar".to_string(), 0, 0)
            } else {
                let channel = CHANNELS[sensor];
                (format!("samples/{channel}/log__{channel}__{time}.jpg"), format!("cal-{sensor}"), WIDTH, HEIGHT)
            };
            data.push(json!({"token": format!("data-{token}"), "sample_token": format!("sample-{s}"), "ego_pose_token": format!("pose-{token}"), "calibrated_sensor_token": calibration, "filename": filename, "fileformat": "", "width": width, "height": height, "timestamp": time, "is_key_frame": true, "next": "", "prev": ""}));
        }
        let (r, t) = car_pose(s);
        annotations.push(json!({"token": format!("ann-{s}"), "sample_token": format!("sample-{s}"), "instance_token": "inst-car", "translation": t, "size": [2.0, 4.0, 1.5], "rotation": r, "num_lidar_pts": 10, "attribute_tokens": [], "visibility_token": "4"}));
    }
    vec![
        (
            "scene",
            json!([{"token": "scene-0", "name": "scene-0061", "log_token": "log-0", "first_sample_token": "sample-0", "last_sample_token": "sample-1", "nbr_samples": 2}]),
        ),
        ("sample", Value::Array(samples)),
        ("sample_data", Value::Array(data)),
        ("ego_pose", Value::Array(poses)),
        ("calibrated_sensor", Value::Array(calibrated)),
        ("sensor", Value::Array(sensors)),
        ("sample_annotation", Value::Array(annotations)),
        ("instance", json!([{"token": "inst-car", "category_token": "cat-car", "nbr_annotations": 2}])),
        (
            "category",
            json!([{"token": "cat-car", "name": "vehicle.car"}, {"token": "cat-cone", "name": "movable_object.trafficcone"}]),
        ),
        ("log", json!([{"token": "log-0", "location": "singapore-onenorth"}])),
    ]
}

/// Writes the data root: `edit` may change the tables first.
fn write_root(dir: &Path, edit: impl FnOnce(&mut Vec<(&'static str, Value)>)) -> PathBuf {
    let root = dir.join("nuscenes");
    let mut tables = tables();
    edit(&mut tables);
    std::fs::create_dir_all(root.join("v1.0-mini")).unwrap();
    for (name, rows) in &tables {
        std::fs::write(root.join(format!("v1.0-mini/{name}.json")), serde_json::to_vec(rows).unwrap()).unwrap();
    }
    let data = tables.iter().find(|(name, _)| *name == "sample_data").unwrap().1.as_array().unwrap().clone();
    for row in data {
        let path = root.join(row["filename"].as_str().unwrap());
        if path.extension().is_some_and(|e| e == "jpg") {
            write_jpeg(&path, 40);
        } else {
            let p = target_point_in_lidar().as_vec3();
            write_sweep(&path, &[[p.x, p.y, p.z, 7.0, 3.0], [0.0, 30.0, -1.0, 1.0, 0.0]]);
        }
    }
    root
}

fn convert(root: &Path, out: &Path, cameras: &[usize]) -> Result<usize, String> {
    let tables = Tables::read(root, NuScenesVersion::Mini).map_err(|e| e.to_string())?;
    convert_scene(&tables, 0, out, cameras, SkyMasks::Lidar, &|_| {}).map(|s| s.frames).map_err(|e| e.to_string())
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
    assert_eq!(values.len(), 8);
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
    let mut sorted = set.clone();
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

    // The export reads back as a nuScenes scene.
    let scene = dggt_data::read_export(&out, &Default::default()).unwrap();
    assert_eq!((scene.frames.len(), scene.cameras.len(), scene.views.len()), (2, 6, 12));
    assert!(scene.views.iter().all(|v| v.files.sky_mask.is_some()));
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
