//! The Argoverse 2 converter on a real log excerpt: its calibration, poses, two lidar sweeps and annotations are
//! real; its camera images are those sweeps' points drawn into each camera with the log's calibration (depth
//! colours, 5x5 px dots on grey). So the exported cameras, read back by the project's export reader, must put
//! each sweep's points on drawn pixels: that checks every axis and pose convention at once. The data lives
//! beside the repository (`../shared/real-data`, or `$DGGT_REAL_DATA`; non-commercial licence, never copied).

use std::path::PathBuf;

use dggt_convert::argoverse2::convert_log;
use dggt_convert::batch::ConvertOptions;
use dggt_convert::depth_flows::DepthFlows;
use dggt_convert::masks::DynamicMaskStyle;
use dggt_convert::sky::SkyMasks;
use dggt_convert::undistort::Lens;
use dggt_data::{DynamicMaskKind, ExportLayout, ExportVariant, read_export};
use image::RgbImage;

use crate::common::real_data;

fn log() -> PathBuf {
    real_data().join("av2/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede")
}

/// The most frequent colour: the grey the points were drawn on.
fn background(image: &RgbImage) -> [u8; 3] {
    let mut counts = std::collections::HashMap::new();
    for p in image.pixels() {
        *counts.entry(p.0).or_insert(0usize) += 1;
    }
    counts.into_iter().max_by_key(|(_, n)| *n).unwrap().0
}

/// Whether a pixel within `radius` of (u, v) differs clearly from the background.
fn drawn_near(image: &RgbImage, grey: [u8; 3], u: f64, v: f64, radius: i64) -> bool {
    let (col, row) = (u.floor() as i64, v.floor() as i64);
    (-radius..=radius).any(|dy| {
        (-radius..=radius).any(|dx| {
            let (x, y) = (col + dx, row + dy);
            if x < 0 || y < 0 || x >= image.width() as i64 || y >= image.height() as i64 {
                return false;
            }
            let p = image.get_pixel(x as u32, y as u32).0;
            p.iter().zip(grey).any(|(&a, b)| a.abs_diff(b) > 40)
        })
    })
}

/// Marks the pixels within `radius` (Chebyshev) of (u, v).
fn stamp(mask: &mut image::GrayImage, u: f64, v: f64, radius: i64) {
    let (col, row) = (u.floor() as i64, v.floor() as i64);
    for y in (row - radius).max(0)..=(row + radius).min(mask.height() as i64 - 1) {
        for x in (col - radius).max(0)..=(col + radius).min(mask.width() as i64 - 1) {
            mask.put_pixel(x as u32, y as u32, image::Luma([1]));
        }
    }
}

#[test]
fn the_log_converts_and_its_lidar_lands_on_the_drawn_pixels() {
    let out = tempfile::tempdir().unwrap();
    let scene_dir = out.path().join("000");
    let summary =
        convert_log(&log(), &scene_dir, (&cameras(&[0, 1, 2, 3, 4, 5, 6]), Lens::AsRecorded), &|_| {}).unwrap();
    assert_eq!((summary.frames, summary.dropped_sweeps), (2, 0));
    assert!(summary.instances > 0);
    assert_eq!(ExportVariant::detect(&scene_dir).unwrap(), ExportVariant::Argoverse2);
    let scene = read_export(&scene_dir, &Default::default()).unwrap();
    assert_eq!((scene.cameras.len(), scene.frames.len()), (7, 2));
    assert_eq!((scene.cameras[0].size.width, scene.cameras[0].size.height), (1550, 2048), "front centre is portrait");
    let layout = ExportLayout::new(&scene_dir);
    let names = ExportVariant::Argoverse2.camera_names();
    let mut masked_pixels = 0;
    for c in 0..7 {
        let mask = dggt_data::images::read_gray(&layout.dynamic_mask(DynamicMaskKind::All, 0, c)).unwrap();
        assert_eq!(mask.dimensions(), (scene.cameras[c].size.width, scene.cameras[c].size.height));
        masked_pixels += mask.pixels().filter(|p| p.0[0] == 255).count();
    }
    println!("{} instances; {masked_pixels} masked pixels in frame 0", summary.instances);
    assert!(masked_pixels > 0, "the log's cars and pedestrians are masked");
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    assert_eq!(info.as_object().unwrap().len(), summary.instances);
    let first = &info["0"]["frame_annotations"];
    assert_eq!(first["frame_idx"][0], 0);
    assert_eq!(first["box_size"][0].as_array().unwrap().len(), 3);
    for frame in 0..2 {
        let points = scene.lidar[frame].as_ref().expect("a sweep per frame").read_in_world().unwrap();
        assert!(points.len() > 90_000, "{}", points.len());
        for (c, camera) in scene.cameras.iter().enumerate() {
            let image = dggt_data::images::read_rgb(&layout.image(frame, c)).unwrap();
            let grey = background(&image);
            let camera_from_world = scene.view(frame, c).world_from_camera.inverse();
            let (mut inside, mut on_drawn, mut shifted_on_drawn) = (0usize, 0usize, 0usize);
            let mut near_a_point = image::GrayImage::new(image.width(), image.height());
            for &p in &points {
                let Some(pixel) = camera.intrinsics.project(camera_from_world.transform_point(p)) else { continue };
                let (w, h) = (camera.size.width as f64, camera.size.height as f64);
                if pixel.x < 40.0 || pixel.y < 40.0 || pixel.x >= w - 40.0 || pixel.y >= h - 40.0 {
                    continue;
                }
                inside += 1;
                stamp(&mut near_a_point, pixel.x, pixel.y, 3);
                on_drawn += drawn_near(&image, grey, pixel.x, pixel.y, 2) as usize;
                // The same points 30 px off: a convention error of that size would land here.
                shifted_on_drawn += drawn_near(&image, grey, pixel.x + 30.0, pixel.y - 30.0, 2) as usize;
            }
            let share = on_drawn as f64 / inside as f64;
            let (mut drawn, mut explained) = (0usize, 0usize);
            for (x, y, p) in image.enumerate_pixels() {
                let inner = x >= 40 && y >= 40 && x + 40 < image.width() && y + 40 < image.height();
                if inner && p.0.iter().zip(grey).any(|(&a, b)| a.abs_diff(b) > 40) {
                    drawn += 1;
                    explained += (near_a_point.get_pixel(x, y).0[0] > 0) as usize;
                }
            }
            let explained_share = explained as f64 / drawn as f64;
            let shifted = shifted_on_drawn as f64 / inside as f64;
            println!(
                "frame {frame} {}: {inside} points in view, {:.2} % within 2 px of a drawn pixel ({:.2} % when \
                 shifted 30 px); {:.2} % of the drawn pixels within 3 px of a projected point",
                names[c],
                share * 100.0,
                shifted * 100.0,
                explained_share * 100.0
            );
            assert!(explained_share > 0.98, "{}: {explained_share}", names[c]);
            assert!(inside > 1000, "{}: {inside}", names[c]);
            assert!(share > 0.98, "{}: {share}", names[c]);
            assert!(shifted < 0.9, "{}: the check tells a 30 px error apart ({shifted})", names[c]);
            let source = log()
                .join("sensors/cameras")
                .join(names[c])
                .join(format!("{}.jpg", [315966265259836000i64, 315966265360032000][frame]));
            assert!(
                std::fs::read(layout.image(frame, c)).unwrap() == std::fs::read(source).unwrap(),
                "JPEG bytes kept"
            );
        }
    }
}

/// A copy of the log whose files are links to the real ones, except those the test replaces.
fn linked_log(dir: &std::path::Path) -> PathBuf {
    let copy = dir.join("log");
    std::fs::create_dir_all(copy.join("calibration")).unwrap();
    for name in ["sensors", "annotations.feather", "city_SE3_egovehicle.feather", "calibration/intrinsics.feather"] {
        std::os::unix::fs::symlink(log().join(name), copy.join(name)).unwrap();
    }
    copy
}

#[test]
fn a_non_unit_quaternion_and_a_missing_table_are_errors_naming_the_file() {
    use arrow_array::{Array, ArrayRef, Float64Array, RecordBatch};
    use std::sync::Arc;

    let dir = tempfile::tempdir().unwrap();
    let copy = linked_log(dir.path());
    let source = std::fs::File::open(log().join("calibration/egovehicle_SE3_sensor.feather")).unwrap();
    let batches: Vec<RecordBatch> =
        arrow_ipc::reader::FileReader::try_new(source, None).unwrap().map(|b| b.unwrap()).collect();
    let batch = &batches[0];
    let qw = batch.column_by_name("qw").unwrap().as_any().downcast_ref::<Float64Array>().unwrap();
    let scaled: Vec<f64> = (0..qw.len()).map(|i| if i == 2 { qw.value(i) * 2.0 } else { qw.value(i) }).collect();
    let columns: Vec<ArrayRef> = batch
        .schema()
        .fields()
        .iter()
        .zip(batch.columns())
        .map(|(field, column)| {
            if field.name() == "qw" { Arc::new(Float64Array::from(scaled.clone())) as ArrayRef } else { column.clone() }
        })
        .collect();
    let damaged = RecordBatch::try_new(batch.schema(), columns).unwrap();
    let target = std::fs::File::create(copy.join("calibration/egovehicle_SE3_sensor.feather")).unwrap();
    let mut writer = arrow_ipc::writer::FileWriter::try_new(target, &damaged.schema()).unwrap();
    writer.write(&damaged).unwrap();
    writer.finish().unwrap();

    let message = convert_log(&copy, &dir.path().join("000"), (&cameras(&[0]), Lens::AsRecorded), &|_| {})
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("egovehicle_SE3_sensor.feather")
            && message.contains("row 2")
            && message.contains("unit quaternion"),
        "{message}"
    );

    std::fs::remove_file(copy.join("city_SE3_egovehicle.feather")).unwrap();
    std::fs::copy(
        log().join("calibration/egovehicle_SE3_sensor.feather"),
        copy.join("calibration/egovehicle_SE3_sensor.feather"),
    )
    .unwrap();
    let message = convert_log(&copy, &dir.path().join("001"), (&cameras(&[0]), Lens::AsRecorded), &|_| {})
        .unwrap_err()
        .to_string();
    assert!(message.contains("city_SE3_egovehicle.feather"), "{message}");
}

fn cameras(ids: &[usize]) -> ConvertOptions {
    ConvertOptions {
        cameras: ids.to_vec(),
        sky_masks: SkyMasks::None,
        depth_flows: DepthFlows::None,
        dynamic_masks: DynamicMaskStyle::Drivestudio,
    }
}

/// One object's box at a frame, from `instances_info.json`: log world <- box, and its size.
struct InstanceBox {
    world_from_box: dggt_geom::glam::DMat4,
    size: dggt_geom::glam::DVec3,
}

/// Every object's boxes by frame index, from the export's `instances/instances_info.json`.
fn instance_boxes(layout: &ExportLayout) -> Vec<std::collections::HashMap<usize, InstanceBox>> {
    use dggt_geom::glam::{DMat4, DVec3};
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    let objects = info.as_object().unwrap().values();
    objects
        .map(|object| {
            let annotations = &object["frame_annotations"];
            let frames = annotations["frame_idx"].as_array().unwrap().iter().map(|f| f.as_u64().unwrap() as usize);
            let poses = annotations["obj_to_world"].as_array().unwrap();
            let sizes = annotations["box_size"].as_array().unwrap();
            frames
                .zip(poses.iter().zip(sizes))
                .map(|(frame, (pose, size))| {
                    let rows: [[f64; 4]; 4] = serde_json::from_value(pose.clone()).unwrap();
                    let size: [f64; 3] = serde_json::from_value(size.clone()).unwrap();
                    let world_from_box = DMat4::from_cols_array_2d(&rows).transpose();
                    (frame, InstanceBox { world_from_box, size: DVec3::from_array(size) })
                })
                .collect()
        })
        .collect()
}

/// Whether a log-world point lies inside the box grown by `margin` on every side (negative: shrunk).
fn inside(object: &InstanceBox, point: dggt_geom::glam::DVec3, margin: f64) -> bool {
    let local = object.world_from_box.inverse().transform_point3(point);
    local.abs().cmple(object.size * 0.5 + margin).all()
}

#[test]
fn depth_flows_move_exactly_the_points_inside_tracked_boxes() {
    use dggt_geom::glam::{DVec2, DVec3};

    let out = tempfile::tempdir().unwrap();
    let scene_dir = out.path().join("000");
    let started = std::time::Instant::now();
    convert_log(&log(), &out.path().join("plain"), (&cameras(&[0, 1, 2, 3, 4, 5, 6]), Lens::AsRecorded), &|_| {})
        .unwrap();
    let plain_s = started.elapsed().as_secs_f64();
    let options = ConvertOptions { depth_flows: DepthFlows::FromBoxes, ..cameras(&[0, 1, 2, 3, 4, 5, 6]) };
    let started = std::time::Instant::now();
    convert_log(&log(), &scene_dir, (&options, Lens::AsRecorded), &|_| {}).unwrap();
    let folder_bytes = |folder: &std::path::Path| -> u64 {
        std::fs::read_dir(folder).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum()
    };
    println!(
        "converted in {plain_s:.2} s, with depth flows in {:.2} s; depth_flows_4/ holds {} bytes, images/ {}",
        started.elapsed().as_secs_f64(),
        folder_bytes(&scene_dir.join("depth_flows_4")),
        folder_bytes(&scene_dir.join("images"))
    );
    let scene = read_export(&scene_dir, &Default::default()).unwrap();
    assert_eq!(scene.depth_source(), Some(dggt_data::DepthSource::DepthFlows4));
    let objects = instance_boxes(&ExportLayout::new(&scene_dir));
    let seconds = scene.frames[1].timestamp - scene.frames[0].timestamp;
    assert!((seconds - 0.1).abs() < 0.01, "consecutive sweeps: {seconds} s");
    let log_from_world = scene.world_from_log.inverse();
    let (mut moving_cells, mut fast_cells, mut static_cells, mut static_in_boxes) = (0usize, 0usize, 0usize, 0usize);
    for frame in 0..2 {
        let (neighbour, step) = if frame == 0 { (1, seconds) } else { (0, -seconds) };
        // The velocity of a point inside each box tracked at both frames (by hand: the box's rigid motion).
        let velocity = |object: &std::collections::HashMap<usize, InstanceBox>, p: DVec3| {
            let (now, then) = (object.get(&frame)?, object.get(&neighbour)?);
            let moved = then.world_from_box.transform_point3(now.world_from_box.inverse().transform_point3(p));
            Some((moved - p) / step)
        };
        for (c, camera) in scene.cameras.iter().enumerate() {
            let map = scene.depth_map(frame, c).unwrap().unwrap();
            let flow = map.flow.as_ref().expect("depth_flows_4 carries flow");
            let world_from_camera = scene.view(frame, c).world_from_camera;
            for (i, &depth) in map.depth.iter().enumerate() {
                if depth <= 0.0 {
                    continue;
                }
                let (row, col) = ((i / map.size.width as usize) as f64, (i % map.size.width as usize) as f64);
                // The cell centre at the return's depth: within 2√2 px of where the return projects.
                let centre = DVec2::new(4.0 * col + 2.0, 4.0 * row + 2.0);
                let in_camera = camera.intrinsics.unproject(centre, depth as f64);
                let p = log_from_world.transform_point(world_from_camera.transform_point(in_camera));
                let reach = 3.0 * depth as f64 / camera.intrinsics.fx + 0.05;
                let f = DVec3::from_array(flow[i].map(f64::from));
                if f != DVec3::ZERO {
                    moving_cells += 1;
                    fast_cells += (f.length() > 1.0) as usize;
                    let expected = objects
                        .iter()
                        .filter(|o| o.get(&frame).is_some_and(|b| inside(b, p, reach)))
                        .filter_map(|o| velocity(o, p))
                        .collect::<Vec<_>>();
                    assert!(
                        !expected.is_empty(),
                        "frame {frame} camera {c} cell {i}: flow {f} outside every tracked box"
                    );
                    let close = expected.iter().any(|e| (*e - f).length() < 0.2 + 0.05 * e.length());
                    assert!(close, "frame {frame} camera {c} cell {i}: flow {f}, the boxes' motion {expected:?}");
                } else {
                    static_cells += 1;
                    let deep = objects.iter().filter(|o| o.get(&frame).is_some_and(|b| inside(b, p, -reach)));
                    let moving = deep.filter_map(|o| velocity(o, p)).find(|v| v.length() > 0.05);
                    assert!(
                        moving.is_none(),
                        "frame {frame} camera {c} cell {i}: static inside a box moving {moving:?}"
                    );
                    static_in_boxes +=
                        objects.iter().any(|o| o.get(&frame).is_some_and(|b| inside(b, p, 0.0))) as usize;
                }
            }
        }
    }
    println!(
        "{moving_cells} cells with flow ({fast_cells} faster than 1 m/s), {static_cells} static ({static_in_boxes} \
         of them in boxes without motion)"
    );
    // Parked cars' boxes jitter by centimetres between sweeps: their flow is small but not zero.
    assert!(fast_cells > 100, "the log's moving objects are seen: {fast_cells}");
    assert!(static_cells > 5 * moving_cells, "{static_cells} static, {moving_cells} with flow");
}

#[test]
fn a_box_of_zero_length_is_an_error_naming_the_annotations_with_depth_flows() {
    // (A NaN length is already refused by the table reader: `expected finite values in length_m`.)
    use arrow_array::{Array, ArrayRef, Float32Array, Float64Array, RecordBatch};
    use std::sync::Arc;

    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("log");
    std::fs::create_dir_all(&copy).unwrap();
    for name in ["sensors", "calibration", "city_SE3_egovehicle.feather"] {
        std::os::unix::fs::symlink(log().join(name), copy.join(name)).unwrap();
    }
    let source = std::fs::File::open(log().join("annotations.feather")).unwrap();
    let batches: Vec<RecordBatch> =
        arrow_ipc::reader::FileReader::try_new(source, None).unwrap().map(|b| b.unwrap()).collect();
    let target = std::fs::File::create(copy.join("annotations.feather")).unwrap();
    let mut writer = arrow_ipc::writer::FileWriter::try_new(target, &batches[0].schema()).unwrap();
    for batch in &batches {
        let columns: Vec<ArrayRef> = batch
            .schema()
            .fields()
            .iter()
            .zip(batch.columns())
            .map(|(field, column)| match field.name().as_str() {
                "length_m" if column.as_any().is::<Float32Array>() => {
                    Arc::new(Float32Array::from(vec![0f32; column.len()])) as ArrayRef
                }
                "length_m" => Arc::new(Float64Array::from(vec![0f64; column.len()])) as ArrayRef,
                _ => column.clone(),
            })
            .collect();
        writer.write(&RecordBatch::try_new(batch.schema(), columns).unwrap()).unwrap();
    }
    writer.finish().unwrap();

    let options = ConvertOptions { depth_flows: DepthFlows::FromBoxes, ..cameras(&[0]) };
    let message =
        convert_log(&copy, &dir.path().join("000"), (&options, Lens::AsRecorded), &|_| {}).unwrap_err().to_string();
    assert!(
        message.contains("annotations.feather") && message.contains("frame 0") && message.contains("box size"),
        "{message}"
    );
}
