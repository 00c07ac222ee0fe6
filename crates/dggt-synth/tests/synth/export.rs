//! End-to-end checks of the synthetic export: reproducibility, geometric consistency of the written cameras
//! and depth, dynamic masks against the written 3D boxes, scene flow against the trajectories, validation.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dggt_data::{DynamicMaskKind, ExportLayout, ExportVariant, images, npy, text};
use dggt_geom::glam::{DVec2, DVec3};
use dggt_geom::{Ego, PinholeIntrinsics, Rigid, WaymoCamera, World, WorldFromCamera, WorldFromEgo, axes};
use dggt_synth::{Object, SynthConfig, SynthError, SynthScene, WorldFromObject, generate, synthesize, write_export};

fn small(seed: u64, frames: usize) -> SynthConfig {
    SynthConfig { seed, frames, cameras: 3, width: 64, height: 48 }
}

fn export(config: &SynthConfig) -> (tempfile::TempDir, SynthScene, ExportLayout) {
    let dir = tempfile::tempdir().unwrap();
    let scene = generate(config).unwrap();
    write_export(&scene, dir.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    let layout = ExportLayout::new(dir.path());
    (dir, scene, layout)
}

/// Every file under `root`, by relative path.
fn all_files(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut pending = vec![root.to_owned()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else {
                files.insert(path.strip_prefix(root).unwrap().to_owned(), std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

fn read_intrinsics(layout: &ExportLayout, camera: usize) -> PinholeIntrinsics {
    let v = text::read_numbers(&layout.intrinsics(camera), 9).unwrap();
    assert!(v[4..].iter().all(|&d| d == 0.0), "no distortion");
    PinholeIntrinsics::new(v[0], v[1], v[2], v[3]).unwrap()
}

/// The camera pose a scene-export reader computes: inv(ego[0]) · ego[t] · extrinsic · M.
fn read_camera_pose(layout: &ExportLayout, frame: usize, camera: usize) -> WorldFromCamera {
    let ego = |f: usize| WorldFromEgo::from_rows(text::read_matrix(&layout.ego_pose(f)).unwrap()).unwrap();
    let anchored: Rigid<World, Ego> = (ego(0).inverse() * ego(frame)).relabel();
    let extrinsic =
        Rigid::<Ego, WaymoCamera>::from_rows(text::read_matrix(&layout.extrinsics(camera)).unwrap()).unwrap();
    anchored * axes::ego_from_opencv_camera(&extrinsic)
}

/// Depth-flow samples of a view: `(continuous pixel, depth, flow)`.
fn read_depth_flow(layout: &ExportLayout, frame: usize, camera: usize) -> Vec<(DVec2, f32, [f32; 3])> {
    let array = npy::read_npy_f32(&layout.depth_flow(frame, camera)).unwrap();
    let [rows, cols, channels] = array.shape[..] else { panic!("shape {:?}", array.shape) };
    assert_eq!(channels, 4, "depth and a 3D flow per sample");
    (0..rows * cols)
        .map(|i| {
            let v = &array.data[i * 4..i * 4 + 4];
            let pixel = DVec2::new((4 * (i % cols)) as f64 + 2.0, (4 * (i / cols)) as f64 + 2.0);
            (pixel, v[0], [v[1], v[2], v[3]])
        })
        .collect()
}

fn time(frame: usize) -> f64 {
    SynthConfig::frame_time(frame)
}

#[test]
fn same_seed_gives_identical_files_and_another_seed_different_images() {
    let config = small(7, 3);
    let (a, b, c) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let summary = synthesize(&config, a.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    synthesize(&config, b.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    synthesize(&SynthConfig { seed: 8, ..config }, c.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    let (files_a, files_b, files_c) = (all_files(a.path()), all_files(b.path()), all_files(c.path()));
    let views = config.frames * config.cameras;
    // Per view: image, sky, 4 dynamic masks, depth-flow; per camera: 2 calibration files; per frame: ego pose;
    // plus the two instance files, timestamps.txt and synth.json.
    assert_eq!(files_a.len(), views * 7 + config.cameras * 2 + config.frames + 4);
    assert_eq!(summary.images, views);
    assert_eq!(files_a.keys().collect::<Vec<_>>(), files_b.keys().collect::<Vec<_>>());
    for (path, bytes) in &files_a {
        assert!(bytes == &files_b[path], "{} differs between two runs with the same seed", path.display());
    }
    assert_eq!(files_a.keys().collect::<Vec<_>>(), files_c.keys().collect::<Vec<_>>());
    let differing = files_a.iter().filter(|(p, bytes)| p.starts_with("images") && *bytes != &files_c[*p]).count();
    assert_eq!(differing, views, "every image changes with the seed");
}

#[test]
fn written_calibration_matches_the_rendered_cameras() {
    let config = SynthConfig { seed: 2, frames: 3, cameras: 3, width: 66, height: 50 };
    let (_dir, scene, layout) = export(&config);
    for camera in 0..3 {
        let k = read_intrinsics(&layout, camera);
        assert_eq!(k, scene.intrinsics());
        assert!(k.fx == k.fy && k.cx == 33.0 && k.cy == 25.0);
        let fov = 2.0 * (33.0 / k.fx).atan();
        assert!((fov.to_degrees() - 78.0).abs() < 1e-9);
        for frame in 0..config.frames {
            let read = read_camera_pose(&layout, frame, camera);
            let rendered = scene.world_from_camera(frame, camera).unwrap();
            assert!(read.max_abs_difference(&rendered) < 1e-12, "frame {frame} camera {camera}");
        }
    }
    let first = WorldFromEgo::from_rows(text::read_matrix(&layout.ego_pose(0)).unwrap()).unwrap();
    assert_eq!(first, WorldFromEgo::IDENTITY, "the world is anchored at the first ego pose");
    // The ego moves forward; the front camera looks along +x, the left one to +y.
    let forward = |camera| scene.world_from_camera(1, camera).unwrap().transform_vector(DVec3::Z);
    assert!(forward(0).x > 0.99 && forward(1).y > 0.6 && forward(2).y < -0.6);
    assert!(read_camera_pose(&layout, 2, 0).translation().x > 1.6 + 0.2 * 7.0 - 0.1);
    let depth = npy::read_npy_f32(&layout.depth_flow(1, 0)).unwrap();
    assert_eq!(depth.shape, vec![12, 16, 4], "integer division of 50x66 by 4");
    let sky = images::read_gray(&layout.sky_mask(1, 0)).unwrap();
    assert_eq!(sky.dimensions(), (66, 50));
    let image = images::read_rgb(&layout.image(1, 0)).unwrap();
    assert_eq!(image.dimensions(), (66, 50));
}

#[test]
fn the_scene_export_reader_reads_the_export() {
    let config = small(9, 3);
    let (dir, scene, _layout) = export(&config);
    let read = dggt_data::read_export(dir.path(), &dggt_data::ExportOptions::default()).unwrap();
    assert_eq!((read.frames.len(), read.cameras.len(), read.views.len()), (3, 3, 9));
    for camera in &read.cameras {
        assert_eq!(camera.intrinsics, scene.intrinsics());
        assert_eq!(camera.size, scene.image_size());
    }
    for view in &read.views {
        let rendered = scene.world_from_camera(view.frame, view.camera).unwrap();
        assert!(view.world_from_camera.max_abs_difference(&rendered) < 1e-12);
        let depth_flow =
            dggt_data::DepthFlowMap::read(view.files.depth_flow.as_ref().unwrap(), scene.image_size()).unwrap();
        assert!(depth_flow.depth.iter().any(|&d| d > 0.0));
        assert!(view.files.sky_mask.is_some() && view.files.fine_dynamic_mask.is_some());
    }
    assert!((read.frames[2].timestamp - 0.2).abs() < 1e-12);
}

#[test]
fn sky_masks_and_depth_agree_with_the_rays() {
    let config = small(4, 2);
    let (_dir, scene, layout) = export(&config);
    let k = scene.intrinsics();
    let mut sky_pixels = 0;
    for camera in 0..3 {
        let pose = read_camera_pose(&layout, 1, camera);
        let sky = images::read_gray(&layout.sky_mask(1, camera)).unwrap();
        for (col, row, value) in sky.enumerate_pixels() {
            assert!(value.0[0] == 0 || value.0[0] == 255);
            let dir = pose.transform_vector(k.unproject(DVec2::new(col as f64 + 0.5, row as f64 + 0.5), 1.0));
            if value.0[0] == 255 {
                sky_pixels += 1;
                assert!(dir.z > 0.0, "sky below the horizon at ({col}, {row})");
            }
        }
        for (pixel, depth, flow) in read_depth_flow(&layout, 1, camera) {
            let dir = pose.transform_vector(k.unproject(pixel, 1.0));
            let hit = scene.cast(pose.translation(), dir, time(1));
            match hit {
                None => assert!(depth == 0.0 && flow == [0.0; 3]),
                Some(hit) => {
                    let z = hit.distance / dir.length();
                    assert!((z - depth as f64).abs() < 1e-4 * z.max(1.0), "{z} vs {depth}");
                }
            }
        }
    }
    assert!(sky_pixels > 100, "the sky is visible: {sky_pixels}");
}

#[test]
fn static_points_reproject_consistently_across_frames() {
    let config = small(3, 6);
    let (_dir, scene, layout) = export(&config);
    let size = scene.image_size();
    let (mut candidates, mut agree, mut beyond) = (0usize, 0usize, 0usize);
    for (frame_a, frame_b) in [(0, 5), (5, 2)] {
        let at_b = scene.at(time(frame_b)).unwrap();
        for camera_a in 0..3 {
            let k_a = read_intrinsics(&layout, camera_a);
            let pose_a = read_camera_pose(&layout, frame_a, camera_a);
            for (pixel, depth, flow) in read_depth_flow(&layout, frame_a, camera_a) {
                if depth == 0.0 || flow != [0.0; 3] {
                    continue;
                }
                let point = pose_a.transform_point(k_a.unproject(pixel, depth as f64));
                for camera_b in 0..3 {
                    let k_b = read_intrinsics(&layout, camera_b);
                    let pose_b = read_camera_pose(&layout, frame_b, camera_b);
                    let Some(uv) = k_b.project(pose_b.inverse().transform_point(point)) else { continue };
                    if uv.x < 0.0 || uv.y < 0.0 || uv.x >= size.width as f64 || uv.y >= size.height as f64 {
                        continue;
                    }
                    candidates += 1;
                    let centre = pose_b.translation();
                    let expected = (point - centre).length();
                    match at_b.cast(centre, point - centre) {
                        Some(hit) if (hit.distance - expected).abs() < 0.03 => agree += 1,
                        // Hidden behind a car that has moved in between: not a static comparison.
                        Some(hit) if hit.distance < expected && hit.dynamic => candidates -= 1,
                        // Hidden from the second viewpoint by static geometry.
                        Some(hit) if hit.distance < expected => {}
                        _ => beyond += 1,
                    }
                }
            }
        }
    }
    assert!(candidates > 400, "{candidates} candidates");
    let fraction = agree as f64 / candidates as f64;
    assert!(fraction > 0.9, "only {agree} of {candidates} static points agree");
    assert!(beyond * 100 <= candidates, "{beyond} of {candidates} points are not on any surface in the other frame");
}

/// A moving instance read from `instances_info.json`: pose per annotated frame and box size.
struct Annotated {
    id: u64,
    box_size: DVec3,
    poses: BTreeMap<usize, WorldFromObject>,
}

fn read_moving_instances(layout: &ExportLayout) -> Vec<Annotated> {
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    let frames: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.frame_instances()).unwrap()).unwrap();
    let numbers =
        |v: &serde_json::Value| -> Vec<f64> { v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect() };
    let mut moving = Vec::new();
    for (key, instance) in info.as_object().unwrap() {
        let id = instance["id"].as_u64().unwrap();
        assert_eq!(key, &id.to_string(), "instances keyed by their id");
        assert_eq!(instance["class_name"], "vehicle", "every instance a vehicle");
        let annotations = &instance["frame_annotations"];
        let frame_idx: Vec<usize> =
            annotations["frame_idx"].as_array().unwrap().iter().map(|f| f.as_u64().unwrap() as usize).collect();
        for &frame in &frame_idx {
            let listed = frames[frame.to_string()].as_array().unwrap();
            assert!(
                listed.iter().any(|v| v.as_u64() == Some(id)),
                "instance {id} annotated but not listed in frame {frame}"
            );
        }
        if !instance["dynamic"].as_bool().unwrap() {
            continue;
        }
        let size = numbers(&instance["box_size"]);
        let poses = frame_idx
            .iter()
            .zip(annotations["obj_to_world"].as_array().unwrap())
            .map(|(&frame, m)| {
                let rows: Vec<Vec<f64>> = m.as_array().unwrap().iter().map(numbers).collect();
                let rows: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| rows[i][j]));
                (frame, Rigid::<World, Object>::from_rows(rows).unwrap())
            })
            .collect();
        moving.push(Annotated { id, box_size: DVec3::new(size[0], size[1], size[2]), poses });
    }
    assert!(moving.len() >= 2, "at least two moving cars");
    moving
}

#[test]
fn dynamic_masks_lie_inside_the_projected_moving_boxes() {
    let config = small(11, 10);
    let (_dir, scene, layout) = export(&config);
    let moving = read_moving_instances(&layout);
    let size = scene.image_size();
    let mut frames_with_dynamic_pixels = 0;
    for frame in 0..config.frames {
        let mut dynamic_pixels = 0;
        for camera in 0..3 {
            let k = read_intrinsics(&layout, camera);
            let camera_from_world = read_camera_pose(&layout, frame, camera).inverse();
            // 2D bounding rectangle of each annotated moving box; a box reaching behind the camera covers the image.
            let rectangles: Vec<(DVec2, DVec2)> = moving
                .iter()
                .filter_map(|instance| instance.poses.get(&frame).map(|pose| (instance, pose)))
                .map(|(instance, pose)| {
                    let half = instance.box_size / 2.0;
                    let corners = dggt_synth::Aabb::new(-half, half).corners();
                    let projected: Option<Vec<DVec2>> = corners
                        .iter()
                        .map(|&c| k.project(camera_from_world.transform_point(pose.transform_point(c))))
                        .collect();
                    match projected {
                        Some(points) => points
                            .iter()
                            .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p))),
                        None => (DVec2::NEG_INFINITY, DVec2::INFINITY),
                    }
                })
                .collect();
            let fine = images::read_gray(&layout.dynamic_mask(DynamicMaskKind::FineAll, frame, camera)).unwrap();
            let coarse = images::read_gray(&layout.dynamic_mask(DynamicMaskKind::All, frame, camera)).unwrap();
            let vehicle = images::read_gray(&layout.dynamic_mask(DynamicMaskKind::Vehicle, frame, camera)).unwrap();
            let human = images::read_gray(&layout.dynamic_mask(DynamicMaskKind::Human, frame, camera)).unwrap();
            assert_eq!(coarse, vehicle);
            assert!(human.pixels().all(|p| p.0[0] == 0));
            assert_eq!(fine.dimensions(), (size.width, size.height));
            for (col, row, value) in fine.enumerate_pixels() {
                let coarse_value = coarse.get_pixel(col, row).0[0];
                assert!(value.0[0] == 0 || coarse_value == 255, "fine mask pixel outside the box mask");
                if coarse_value == 0 {
                    continue;
                }
                let centre = DVec2::new(col as f64 + 0.5, row as f64 + 0.5);
                let inside =
                    rectangles.iter().any(|(lo, hi)| centre.cmpge(*lo - 1.0).all() && centre.cmple(*hi + 1.0).all());
                assert!(
                    inside,
                    "dynamic pixel ({col}, {row}) of frame {frame} camera {camera} is outside every moving box"
                );
                dynamic_pixels += (value.0[0] == 255) as usize;
            }
        }
        frames_with_dynamic_pixels += (dynamic_pixels > 0) as usize;
    }
    assert!(frames_with_dynamic_pixels >= 6, "only {frames_with_dynamic_pixels} frames show moving cars");
    // Moving cars drive well above 1 m/s, one of them along an arc.
    let yaw_changes: Vec<f64> = moving
        .iter()
        .map(|m| {
            let (first, last) = (m.poses.values().next().unwrap(), m.poses.values().last().unwrap());
            first.rotation().angle_between(last.rotation())
        })
        .collect();
    for instance in &moving {
        let object = scene.object(instance.id as u32).unwrap();
        assert!(object.motion().unwrap().speed > 3.0);
    }
    assert!(yaw_changes.iter().any(|&a| a > 0.2), "a moving car turns: {yaw_changes:?}");
}

#[test]
fn flow_matches_the_trajectories_and_is_zero_on_static_surfaces() {
    let config = small(5, 10);
    let (_dir, scene, layout) = export(&config);
    let moving = read_moving_instances(&layout);
    let (mut dynamic_samples, mut static_samples) = (0, 0);
    for frame in 1..config.frames - 1 {
        let at = scene.at(time(frame)).unwrap();
        for camera in 0..3 {
            let k = read_intrinsics(&layout, camera);
            let pose = read_camera_pose(&layout, frame, camera);
            for (pixel, depth, flow) in read_depth_flow(&layout, frame, camera) {
                if depth == 0.0 {
                    assert_eq!(flow, [0.0; 3], "sky has no flow");
                    continue;
                }
                let flow = DVec3::new(flow[0] as f64, flow[1] as f64, flow[2] as f64);
                let point = pose.transform_point(k.unproject(pixel, depth as f64));
                let hit = at.cast(pose.translation(), point - pose.translation()).expect("a surface where depth > 0");
                if !hit.dynamic {
                    assert_eq!(flow, DVec3::ZERO, "static surface {:?} with flow", hit.kind);
                    static_samples += 1;
                    continue;
                }
                dynamic_samples += 1;
                assert!(flow.length() > 1.0);
                // Exact: central difference of the trajectory with a tiny step.
                let object = scene.object(hit.object).unwrap();
                let local = object.world_from_object(time(frame)).inverse().transform_point(point);
                let h = 1e-4;
                let at_time = |t: f64| object.world_from_object(t).transform_point(local);
                let numeric = (at_time(time(frame) + h) - at_time(time(frame) - h)) / (2.0 * h);
                assert!((numeric - flow).length() < 1e-3 + 1e-4 * numeric.length(), "{numeric} vs {flow}");
                // From the files: central difference of the written boxes over the neighbouring frames.
                let instance = moving.iter().find(|m| m.id == hit.object as u64).expect("a written moving instance");
                let (Some(before), Some(now), Some(after)) =
                    (instance.poses.get(&(frame - 1)), instance.poses.get(&frame), instance.poses.get(&(frame + 1)))
                else {
                    continue;
                };
                let local = now.inverse().transform_point(point);
                let written = (after.transform_point(local) - before.transform_point(local)) / 0.2;
                assert!((written - flow).length() < 0.05 + 0.1 * flow.length(), "{written} vs {flow}");
            }
        }
    }
    assert!(dynamic_samples >= 10, "{dynamic_samples} dynamic samples");
    assert!(static_samples > 1000, "{static_samples} static samples");
}

#[test]
fn invalid_configurations_are_errors() {
    let valid = small(1, 2);
    let invalid = [
        SynthConfig { frames: 0, ..valid },
        SynthConfig { frames: 5000, ..valid },
        SynthConfig { cameras: 0, ..valid },
        SynthConfig { cameras: 4, ..valid },
        SynthConfig { width: 0, ..valid },
        SynthConfig { height: 0, ..valid },
        SynthConfig { width: 3, ..valid },
        SynthConfig { height: 100_000, ..valid },
    ];
    for config in invalid {
        assert!(matches!(generate(&config), Err(SynthError::InvalidConfig(_))), "{config:?}");
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("scene");
        assert!(matches!(
            synthesize(&config, &out, ExportVariant::Waymo, dggt_synth::Sweeps::Skip),
            Err(SynthError::InvalidConfig(_))
        ));
        assert!(!out.exists(), "nothing is written for an invalid configuration");
    }
    let scene = generate(&valid).unwrap();
    assert!(matches!(scene.render_view(2, 0), Err(SynthError::NoSuchView { .. })));
    assert!(scene.cast(DVec3::ZERO, DVec3::X, f64::NAN).is_none());
    assert!(scene.cast(DVec3::new(0.0, 0.0, 1.0), DVec3::ZERO, 0.0).is_none());
}
