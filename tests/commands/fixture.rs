//! The bundled synthetic fixture: it is reproducible from its recorded command (every file but the images byte
//! for byte, the images pixel for pixel within what a JPEG or PNG encoder may change), and its ground truth is
//! geometrically consistent when read back through the scene-export reader (independently of the generator).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use dggt_data::{DepthFlowMap, ExportOptions, Scene, images, read_export};
use dggt_geom::glam::{DVec2, DVec3};
use dggt_geom::{PinholeIntrinsics, Rigid, World};

fn fixture() -> PathBuf {
    dggt_test_data::fixture("synth-s0")
}

/// Every file under `root`, by path relative to it.
fn files_under(root: &Path) -> BTreeMap<PathBuf, PathBuf> {
    let mut files = BTreeMap::new();
    let mut stack = vec![root.to_owned()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.insert(path.strip_prefix(root).unwrap().to_owned(), path);
            }
        }
    }
    files
}

/// What a regenerated image may differ by, in 8-bit levels: an encoder upgrade may change JPEG's rounding, never
/// the picture; PNG is lossless, so its pixels must match exactly.
#[derive(Debug, Clone, Copy)]
struct PixelTolerance {
    max: u8,
    mean: f64,
}

const JPEG_TOLERANCE: PixelTolerance = PixelTolerance { max: 12, mean: 1.0 };
const PNG_TOLERANCE: PixelTolerance = PixelTolerance { max: 0, mean: 0.0 };

/// Decoded samples of an image file (grey images as one channel, colour as three).
fn decoded(path: &Path) -> (u32, u32, Vec<u8>) {
    let image = image::open(path).unwrap_or_else(|e| panic!("{} does not decode: {e}", path.display()));
    let (width, height) = (image.width(), image.height());
    let samples = match image.color().channel_count() {
        1 => image.into_luma8().into_raw(),
        _ => image.into_rgb8().into_raw(),
    };
    (width, height, samples)
}

fn assert_same_pixels(committed: &Path, regenerated: &Path, tolerance: PixelTolerance) {
    let (a, b) = (decoded(committed), decoded(regenerated));
    assert_eq!((a.0, a.1, a.2.len()), (b.0, b.1, b.2.len()), "{}: size or channels differ", committed.display());
    let differences: Vec<u8> = a.2.iter().zip(&b.2).map(|(x, y)| x.abs_diff(*y)).collect();
    let max = differences.iter().copied().max().unwrap_or(0);
    let mean = differences.iter().map(|&d| f64::from(d)).sum::<f64>() / differences.len().max(1) as f64;
    assert!(
        max <= tolerance.max && mean <= tolerance.mean,
        "{} differs from the regenerated image by up to {max} levels (mean {mean:.3}); allowed {tolerance:?}",
        committed.display()
    );
}

#[test]
fn fixture_regenerates_from_its_command() {
    let out = tempfile::tempdir().unwrap();
    let target = out.path().join("synth-s0");
    let status = Command::new(env!("CARGO_BIN_EXE_dggt"))
        .args(["synth", "--out"])
        .arg(&target)
        .args(["--seed", "0", "--frames", "20", "--cameras", "3", "--width", "160", "--height", "112"])
        .status()
        .unwrap();
    assert!(status.success());
    let committed = files_under(&fixture());
    let regenerated = files_under(&target);
    let names = |m: &BTreeMap<PathBuf, PathBuf>| m.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(&committed), names(&regenerated), "the fixture's file list changed");
    let mut images = 0;
    for (name, path) in &committed {
        let extension = name.extension().and_then(|e| e.to_str()).unwrap_or_default().to_ascii_lowercase();
        match extension.as_str() {
            "jpg" | "jpeg" => assert_same_pixels(path, &regenerated[name], JPEG_TOLERANCE),
            "png" => assert_same_pixels(path, &regenerated[name], PNG_TOLERANCE),
            _ => {
                let same = std::fs::read(path).unwrap() == std::fs::read(&regenerated[name]).unwrap();
                assert!(same, "{} differs from the regenerated file", name.display());
                continue;
            }
        }
        images += 1;
    }
    assert!(images >= 60, "only {images} images were compared");
}

fn read_fixture() -> Scene {
    read_export(&fixture(), &ExportOptions::default()).unwrap()
}

/// Quarter-resolution intrinsics: cell `(c, r)` is centred at full-resolution `(4c + 2, 4r + 2)`.
fn quarter(k: &PinholeIntrinsics) -> PinholeIntrinsics {
    k.scaled(0.25, 0.25)
}

#[test]
fn static_points_from_two_frames_land_on_the_same_surface() {
    let scene = read_fixture();
    let mut total = Reprojection::default();
    for (c, camera) in scene.cameras.iter().enumerate() {
        for (a, b) in [(4, 8), (12, 9)] {
            let r = reproject_static_points(&scene, c, a, b, &quarter(&camera.intrinsics));
            total = Reprojection {
                candidates: total.candidates + r.candidates,
                agreeing: total.agreeing + r.agreeing,
                in_front: total.in_front + r.in_front,
            };
        }
    }
    let Reprojection { candidates, agreeing, in_front } = total;
    assert!(candidates > 600, "only {candidates} static points are visible in both frames");
    // Points hidden in frame b behind a nearer static object (poles, trees, corners) disagree legitimately; a
    // point in front of what frame b sees would contradict the geometry.
    assert!(agreeing as f64 > 0.85 * candidates as f64, "{agreeing} of {candidates} static points agree");
    assert!((in_front as f64) < 0.02 * candidates as f64, "{in_front} of {candidates} points float in front");

    // The check has teeth: with a 5 % focal-length error many points float in front of the surface.
    let camera = &scene.cameras[0];
    let wrong = reproject_static_points(&scene, 0, 4, 8, &quarter(&camera.intrinsics).scaled(1.05, 1.05));
    assert!((wrong.in_front as f64) > 0.08 * wrong.candidates as f64, "{wrong:?} with wrong intrinsics");
}

#[derive(Debug, Default)]
struct Reprojection {
    /// Static points of frame `a` that project onto static surface cells of frame `b`.
    candidates: usize,
    /// ... whose depth matches what frame `b` sees there.
    agreeing: usize,
    /// ... that would lie in front of what frame `b` sees (impossible for consistent geometry).
    in_front: usize,
}

/// Unprojects the static depth cells of frame `a` and compares them with the depth frame `b` sees where they
/// project.
fn reproject_static_points(scene: &Scene, camera: usize, a: usize, b: usize, k: &PinholeIntrinsics) -> Reprojection {
    let size = scene.cameras[camera].size;
    let depth_a = DepthFlowMap::read(scene.view(a, camera).files.depth_flow.as_ref().unwrap(), size).unwrap();
    let depth_b = DepthFlowMap::read(scene.view(b, camera).files.depth_flow.as_ref().unwrap(), size).unwrap();
    let [flow_a, flow_b] = [&depth_a, &depth_b].map(|map| map.flow.as_ref().expect("depth_flows_4 has flow"));
    let world_from_a = scene.view(a, camera).world_from_camera;
    let b_from_world: Rigid<dggt_geom::Camera, World> = scene.view(b, camera).world_from_camera.inverse();
    let (w, h) = (depth_a.size.width as usize, depth_a.size.height as usize);
    let mut result = Reprojection::default();
    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            let d = depth_a.depth[i] as f64;
            if d <= 0.0 || d > 40.0 || flow_a[i] != [0.0; 3] {
                continue;
            }
            let centre = DVec2::new(col as f64 + 0.5, row as f64 + 0.5);
            let world = world_from_a.transform_point(k.unproject(centre, d));
            let in_b = b_from_world.transform_point(world);
            let Some(pixel) = k.project(in_b) else { continue };
            // The four cells around the projection (cell centres sit at half-integers).
            let (c0, r0) = ((pixel.x - 0.5).floor(), (pixel.y - 0.5).floor());
            if c0 < 0.0 || r0 < 0.0 || c0 + 1.0 >= w as f64 || r0 + 1.0 >= h as f64 {
                continue;
            }
            let (c0, r0) = (c0 as usize, r0 as usize);
            let around = [r0 * w + c0, r0 * w + c0 + 1, (r0 + 1) * w + c0, (r0 + 1) * w + c0 + 1];
            if around.iter().any(|&j| depth_b.depth[j] <= 0.0 || flow_b[j] != [0.0; 3]) {
                continue;
            }
            result.candidates += 1;
            // Frame b sees the same surface there: the depth lies within the range of the surrounding cells.
            let (lo, hi) = around.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &j| {
                let v = depth_b.depth[j] as f64;
                (lo.min(v), hi.max(v))
            });
            let tolerance = 0.01 * in_b.z + 0.02;
            if in_b.z < lo - tolerance {
                result.in_front += 1;
            } else if in_b.z < hi + tolerance {
                result.agreeing += 1;
            }
        }
    }
    result
}

#[derive(serde::Deserialize)]
struct Instance {
    dynamic: bool,
    frame_annotations: Annotations,
}

#[derive(serde::Deserialize)]
struct Annotations {
    frame_idx: Vec<usize>,
    obj_to_world: Vec<[[f64; 4]; 4]>,
    box_size: Vec<[f64; 3]>,
}

#[test]
fn moving_boxes_cover_the_dynamic_masks() {
    let scene = read_fixture();
    let text = std::fs::read_to_string(fixture().join("instances/instances_info.json")).unwrap();
    let instances: BTreeMap<String, Instance> = serde_json::from_str(&text).unwrap();
    let mut frames_with_motion = 0;
    for frame in 0..scene.frames.len() {
        for (c, camera) in scene.cameras.iter().enumerate() {
            let view = scene.view(frame, c);
            let camera_from_world = view.world_from_camera.inverse();
            let rectangles: Vec<(DVec2, DVec2)> = instances
                .values()
                .filter(|i| i.dynamic)
                .filter_map(|i| {
                    let at = i.frame_annotations.frame_idx.iter().position(|&f| f == frame)?;
                    let world_from_box: Rigid<World, World> =
                        Rigid::from_rows(i.frame_annotations.obj_to_world[at]).unwrap();
                    let half = DVec3::from_array(i.frame_annotations.box_size[at]) / 2.0;
                    let corners: Vec<DVec2> = (0..8)
                        .filter_map(|n| {
                            let sign = |bit: i32| if n & bit == 0 { -1.0 } else { 1.0 };
                            let local = half * DVec3::new(sign(1), sign(2), sign(4));
                            let p = camera_from_world.transform_point(world_from_box.transform_point(local));
                            camera.intrinsics.project(DVec3::new(p.x, p.y, p.z.max(0.05)))
                        })
                        .collect();
                    let min = corners.iter().fold(DVec2::splat(f64::MAX), |m, p| m.min(*p));
                    let max = corners.iter().fold(DVec2::splat(f64::MIN), |m, p| m.max(*p));
                    Some((min - 1.0, max + 1.0))
                })
                .collect();
            let mask = images::read_gray(view.files.fine_dynamic_mask.as_ref().unwrap()).unwrap();
            let mut dynamic_pixels = 0;
            for (x, y, value) in mask.enumerate_pixels() {
                if value.0[0] < 128 {
                    continue;
                }
                dynamic_pixels += 1;
                let centre = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                assert!(
                    rectangles.iter().any(|(lo, hi)| centre.cmpge(*lo).all() && centre.cmple(*hi).all()),
                    "frame {frame} camera {c}: dynamic pixel ({x}, {y}) lies outside every moving box"
                );
            }
            if c == 0 && dynamic_pixels > 20 {
                frames_with_motion += 1;
            }
        }
    }
    assert!(frames_with_motion >= 10, "moving cars are visible in only {frames_with_motion} front frames");
}

#[test]
fn training_stream_serves_multi_camera_samples_with_masks() {
    use dggt_data::{LoaderOptions, Preprocess, Sampler, SamplerConfig, training_stream};
    let scene = std::sync::Arc::new(read_fixture());
    let sampler = Sampler::new(SamplerConfig::default(), scene.frames.len(), scene.cameras.len()).unwrap();
    let preprocess = Preprocess { target_width: 70, patch_size: 14, crop_to_square: true };
    let stream = training_stream(scene, sampler, preprocess, 3, 0, LoaderOptions::default()).unwrap();
    let (mut saw_dynamic, mut saw_sky) = (false, false);
    for loaded in stream.take(4) {
        let loaded = loaded.unwrap();
        let n = loaded.sample.input_frames.len();
        assert_eq!((loaded.inputs.len(), loaded.targets.len()), (3 * n, 6 * n));
        for view in loaded.inputs.iter().chain(&loaded.targets) {
            assert_eq!((view.image.size.width, view.image.size.height), (70, 56));
            let sky = view.sky_mask.as_ref().expect("the fixture has sky masks");
            assert!(sky.coverage() < 0.6, "sky covers {}", sky.coverage());
            saw_sky |= sky.coverage() > 0.05;
            saw_dynamic |= view.dynamic_mask.as_ref().expect("the fixture has dynamic masks").coverage() > 0.0;
        }
        let cameras: Vec<usize> = loaded.inputs[..3].iter().map(|v| v.camera).collect();
        assert_eq!(cameras, [0, 1, 2], "views are frame-major");
    }
    assert!(saw_dynamic && saw_sky);
}
