//! A tiny nuScenes data root written by the tests: devkit tables for one scene of two samples, six 80 x 60
//! cameras (uniform JPEGs), LIDAR_TOP sweeps of three points (one on the car) and one annotated car, with the
//! poses that build them.

use std::path::{Path, PathBuf};

use dggt_geom::glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::{Value, json};

pub const CHANNELS: [&str; 6] =
    ["CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK_LEFT", "CAM_BACK_RIGHT", "CAM_BACK"];
pub const YAWS_DEG: [f64; 6] = [0.0, 55.0, -55.0, 110.0, -110.0, 180.0];
pub const FX: f64 = 50.0;
pub const CX: f64 = 40.0;
pub const CY: f64 = 30.0;
pub const WIDTH: u32 = 80;
pub const HEIGHT: u32 = 60;
/// The front camera's mounting: x forward, 1.5 m up.
pub const CAMERA_OFFSET: [f64; 3] = [1.5, 0.0, 1.5];
/// Where the test puts a lidar point: this pixel of CAM_FRONT at sample 0, this far away.
pub const TARGET_PIXEL: (f64, f64, f64) = (20.5, 25.5, 8.0);

pub fn wxyz(q: DQuat) -> [f64; 4] {
    [q.w, q.x, q.y, q.z]
}

/// OpenCV camera axes on a forward-left-up ego, turned by `yaw`: camera z forward, x right, y down.
pub fn ego_from_camera_rotation(yaw: f64) -> DQuat {
    let front = DMat3::from_cols(DVec3::NEG_Y, DVec3::NEG_Z, DVec3::X);
    DQuat::from_rotation_z(yaw) * DQuat::from_mat3(&front)
}

pub fn matrix(rotation: [f64; 4], translation: [f64; 3]) -> DMat4 {
    let q = DQuat::from_xyzw(rotation[1], rotation[2], rotation[3], rotation[0]);
    DMat4::from_rotation_translation(q, DVec3::from_array(translation))
}

/// The ego pose of every reading: facing world +y (yaw 90°), 5 m further along y per sample, with a small
/// offset per sensor (readings at different times).
pub fn ego_pose(sample: usize, sensor: usize) -> ([f64; 4], [f64; 3]) {
    ego_pose_at(sample as f64, sensor)
}

/// [`ego_pose`] at a position between samples (0.5: the non-key-frame reading between them).
pub fn ego_pose_at(position: f64, sensor: usize) -> ([f64; 4], [f64; 3]) {
    let yaw = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
    (wxyz(yaw), [100.0 - 0.1 * sensor as f64, 200.0 + 5.0 * position, 0.0])
}

/// The readings of every sensor: key frames of samples 0 and 1 and one non-key-frame reading between them
/// (whose sample is the next one, as in nuScenes), chained by `next`: (label, position, sample, key frame).
pub const READINGS: [(&str, f64, usize, bool); 3] = [("s0", 0.0, 0, true), ("m", 0.5, 1, false), ("s1", 1.0, 1, true)];

pub fn lidar_calibration() -> ([f64; 4], [f64; 3]) {
    (wxyz(DQuat::from_rotation_z(-std::f64::consts::FRAC_PI_2)), [0.9, 0.0, 1.8])
}

pub fn camera_calibration(camera: usize) -> ([f64; 4], [f64; 3]) {
    let yaw = YAWS_DEG[camera].to_radians();
    let offset = DQuat::from_rotation_z(yaw) * DVec3::from_array(CAMERA_OFFSET);
    (wxyz(ego_from_camera_rotation(yaw)), offset.to_array())
}

pub fn world_from(pose: ([f64; 4], [f64; 3])) -> DMat4 {
    matrix(pose.0, pose.1)
}

/// The car: 12 m ahead of the front camera's ego at each sample, 1 m up, heading with the ego; w, l, h = 2, 4, 1.5.
pub fn car_pose(sample: usize) -> ([f64; 4], [f64; 3]) {
    let pose = ego_pose(sample, 0);
    let centre = world_from(pose).transform_point3(DVec3::new(12.0, 0.0, 1.0));
    (pose.0, centre.to_array())
}

/// The car's speed along world +y: 5 m per sample, samples 0.5 s apart (m/s).
pub const CAR_SPEED: f64 = 10.0;
/// Where the test puts a lidar point on the car: 0.3 m right of its centre (box coordinates).
pub const ON_THE_CAR: [f64; 3] = [0.0, -0.3, 0.0];

/// The point [`ON_THE_CAR`] in the LIDAR_TOP frame of the reading at `position` (0, 0.5, 1: see [`READINGS`]),
/// where the car is where the ego (which it keeps pace with) puts it.
pub fn car_point_in_lidar(position: f64) -> DVec3 {
    let (r, t) = ego_pose_at(position, 0);
    let centre = world_from((r, t)).transform_point3(DVec3::new(12.0, 0.0, 1.0));
    let point = world_from((r, centre.to_array())).transform_point3(DVec3::from_array(ON_THE_CAR));
    let world_from_lidar = world_from(ego_pose_at(position, 6)) * world_from(lidar_calibration());
    world_from_lidar.inverse().transform_point3(point)
}

/// The lidar point (in the LIDAR_TOP frame of sample 0) that CAM_FRONT sees at [`TARGET_PIXEL`].
pub fn target_point_in_lidar() -> DVec3 {
    let (u, v, depth) = TARGET_PIXEL;
    let in_camera = DVec3::new((u - CX) / FX * depth, (v - CY) / FX * depth, depth);
    let world_from_camera = world_from(ego_pose(0, 0)) * world_from(camera_calibration(0));
    let world_from_lidar = world_from(ego_pose(0, 6)) * world_from(lidar_calibration());
    world_from_lidar.inverse().transform_point3(world_from_camera.transform_point3(in_camera))
}

pub fn write_jpeg(path: &Path, shade: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(WIDTH, HEIGHT, image::Rgb([shade, 100, 50])).save(path).unwrap();
}

pub fn write_sweep(path: &Path, points: &[[f32; 5]]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
}

/// The tables of the tiny scene, by table name.
pub fn tables() -> Vec<(&'static str, Value)> {
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
    for (i, (label, position, sample, key)) in READINGS.into_iter().enumerate() {
        let time = 1_000_000 + (500_000.0 * position) as i64;
        let folder = if key { "samples" } else { "sweeps" };
        for sensor in 0..7 {
            let (r, t) = ego_pose_at(position, sensor);
            let token = format!("{label}-{sensor}");
            let next = READINGS.get(i + 1).map_or(String::new(), |(next, ..)| format!("data-{next}-{sensor}"));
            poses.push(json!({"token": format!("pose-{token}"), "translation": t, "rotation": r, "timestamp": time}));
            let (filename, calibration, width, height) = match CHANNELS.get(sensor) {
                None => (format!("{folder}/LIDAR_TOP/log__LIDAR_TOP__{time}.pcd.bin"), "cal-lidar".to_string(), 0, 0),
                Some(channel) => {
                    (format!("{folder}/{channel}/log__{channel}__{time}.jpg"), format!("cal-{sensor}"), WIDTH, HEIGHT)
                }
            };
            data.push(json!({"token": format!("data-{token}"), "sample_token": format!("sample-{sample}"), "ego_pose_token": format!("pose-{token}"), "calibrated_sensor_token": calibration, "filename": filename, "fileformat": "", "width": width, "height": height, "timestamp": time, "is_key_frame": key, "next": next, "prev": ""}));
        }
    }
    for s in 0..2 {
        let time = 1_000_000 + 500_000 * s as i64;
        let next = if s == 0 { "sample-1".to_string() } else { String::new() };
        let prev = if s == 1 { "sample-0".to_string() } else { String::new() };
        samples.push(json!({"token": format!("sample-{s}"), "timestamp": time, "scene_token": "scene-0", "next": next, "prev": prev}));
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
pub fn write_root(dir: &Path, edit: impl FnOnce(&mut Vec<(&'static str, Value)>)) -> PathBuf {
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
            let position = (row["timestamp"].as_i64().unwrap() - 1_000_000) as f64 / 500_000.0;
            let car = car_point_in_lidar(position).as_vec3();
            // The last return, high up behind the vehicle, is the sweep's top beam: the target's column lies
            // below it, so the beams above the target passed into the sky.
            let points = [
                [p.x, p.y, p.z, 7.0, 3.0],
                [0.0, 30.0, -1.0, 1.0, 0.0],
                [car.x, car.y, car.z, 2.0, 1.0],
                [0.0, -30.0, 12.0, 1.0, 5.0],
            ];
            write_sweep(&path, &points);
        }
    }
    root
}
