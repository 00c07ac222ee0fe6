//! Every writer read back by its reader: PLY header, vertex count and values; COLMAP cameras and poses;
//! nerfstudio camera-to-world; camera JSON; depth as `.npy` and 16-bit PNG; masks.

use dggt_formats::cameras_json::{CameraRecord, Convention, read_cameras_json, write_cameras_json};
use dggt_formats::colmap::{ColmapCamera, ColmapImage, read_cameras_txt, read_images_txt, write_colmap};
use dggt_formats::depth::{read_depth_npy, read_depth_png16, scale_for, write_depth_npy, write_depth_png16};
use dggt_formats::masks::{read_mask_png, write_binary_png, write_probability_png};
use dggt_formats::nerfstudio::{NerfstudioFrame, read_transforms, write_transforms};
use dggt_formats::ply::{GaussianCloud, INRIA_PROPERTIES, read_ply, write_ply};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{ImageSize, PinholeIntrinsics, WorldFromCamera};

/// A deterministic pseudo-random sequence in `[0, 1)`.
fn noise(seed: u32) -> impl FnMut() -> f32 {
    let mut state = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / (1u32 << 24) as f32
    }
}

fn cloud(count: usize) -> GaussianCloud {
    let mut r = noise(7);
    let mut cloud = GaussianCloud::default();
    for _ in 0..count {
        cloud.means.push([r() * 20.0 - 10.0, r() * 4.0 - 2.0, r() * 50.0]);
        let q = [r() - 0.5, r() - 0.5, r() - 0.5, r() - 0.5];
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        cloud.quats_wxyz.push(q.map(|v| v / n));
        cloud.scales.push([r() * 0.5 + 1e-3, r() * 0.1 + 1e-3, r() + 1e-3]);
        cloud.opacities.push(r() * 0.98 + 0.01);
        cloud.colors.push([r(), r(), r()]);
    }
    cloud
}

fn pose(i: usize) -> WorldFromCamera {
    let yaw = 0.1 * i as f64 - 0.3;
    let rotation = DQuat::from_rotation_y(yaw) * DQuat::from_rotation_x(0.05 * i as f64);
    WorldFromCamera::from_rotation_translation(rotation, DVec3::new(1.5 * i as f64, -0.2, 123.456 + 7.0 * i as f64))
        .unwrap()
}

fn intrinsics(i: usize) -> PinholeIntrinsics {
    PinholeIntrinsics::new(100.0 + i as f64 * 0.123, 101.5, 42.0 + i as f64 * 0.01, 28.25).unwrap()
}

#[test]
fn ply_round_trips_with_the_inria_header() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("static.ply");
    let original = cloud(257);
    write_ply(&path, &original).unwrap();

    let bytes = std::fs::read(&path).unwrap();
    let header_end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&bytes[..header_end]).unwrap();
    // Exactly INRIA 3DGS's header for SH degree 0, the layout SuperSplat and Brush load.
    let expected = "ply\nformat binary_little_endian 1.0\nelement vertex 257\n\
        property float x\nproperty float y\nproperty float z\n\
        property float nx\nproperty float ny\nproperty float nz\n\
        property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n\
        property float opacity\n\
        property float scale_0\nproperty float scale_1\nproperty float scale_2\n\
        property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n\
        end_header\n";
    assert_eq!(header, expected);
    assert_eq!(bytes.len() - header_end, 257 * 17 * 4);

    let read = read_ply(&path).unwrap();
    assert_eq!(read.count, 257);
    assert_eq!(read.properties, INRIA_PROPERTIES.map(String::from).to_vec());
    // Stored values are pre-activation: the first vertex checked by hand.
    let (o, s) = (original.opacities[0], original.scales[0]);
    assert!((read.value(0, "opacity").unwrap() - (o / (1.0 - o)).ln()).abs() < 1e-5);
    assert!((read.value(0, "scale_2").unwrap() - s[2].ln()).abs() < 1e-6);
    assert!((read.value(0, "f_dc_1").unwrap() - (original.colors[0][1] - 0.5) / 0.282_094_8).abs() < 1e-5);
    assert_eq!(read.value(0, "nx"), Some(0.0));

    let back = read.to_cloud().unwrap();
    assert_eq!(back.len(), original.len());
    let worst = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let flat4 = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<_>>();
    assert_eq!(back.means, original.means);
    assert!(worst(&flat3(&back.scales), &flat3(&original.scales)) < 1e-6);
    assert!(worst(&back.opacities, &original.opacities) < 1e-6);
    assert!(worst(&flat3(&back.colors), &flat3(&original.colors)) < 1e-6);
    assert!(worst(&flat4(&back.quats_wxyz), &flat4(&original.quats_wxyz)) < 1e-6);

    // An empty cloud is a valid file with zero vertices.
    write_ply(&path, &GaussianCloud::default()).unwrap();
    assert_eq!(read_ply(&path).unwrap().count, 0);
    // A truncated file is an error naming it.
    std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
    let error = read_ply(&path).unwrap_err().to_string();
    assert!(error.contains("static.ply") && error.contains("bytes after the header"), "{error}");
}

#[test]
fn colmap_round_trips_poses_and_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let size = ImageSize::new(84, 56).unwrap();
    let cameras: Vec<ColmapCamera> =
        (0..5).map(|i| ColmapCamera { id: i as u32 + 1, size, intrinsics: intrinsics(i) }).collect();
    let images: Vec<ColmapImage> = (0..5)
        .map(|i| ColmapImage {
            id: i as u32 + 1,
            camera_id: i as u32 + 1,
            name: format!("{i:03}_0.png"),
            camera_from_world: pose(i).inverse(),
        })
        .collect();
    write_colmap(dir.path(), &cameras, &images).unwrap();
    assert!(dir.path().join("points3D.txt").is_file());
    let text = std::fs::read_to_string(dir.path().join("cameras.txt")).unwrap();
    assert!(text.lines().any(|l| l.starts_with("1 PINHOLE 84 56 ")), "{text}");

    let cameras_back = read_cameras_txt(&dir.path().join("cameras.txt")).unwrap();
    assert_eq!(cameras_back, cameras);
    let images_back = read_images_txt(&dir.path().join("images.txt")).unwrap();
    assert_eq!(images_back.len(), images.len());
    for (a, b) in images.iter().zip(&images_back) {
        assert_eq!((a.id, a.camera_id, &a.name), (b.id, b.camera_id, &b.name));
        let error = a.camera_from_world.max_abs_difference(&b.camera_from_world);
        assert!(error < 1e-6, "image {}: pose differs by {error}", a.name);
        // Camera-from-world: the stored pose maps the camera centre to the origin.
        let centre = pose(a.id as usize - 1).translation();
        assert!(b.camera_from_world.transform_point(centre).length() < 1e-6);
    }

    std::fs::write(dir.path().join("images.txt"), "1 1 0 0 0 0 0 0 1\n").unwrap();
    let error = read_images_txt(&dir.path().join("images.txt")).unwrap_err().to_string();
    assert!(error.contains("images.txt") && error.contains("line 1"), "{error}");
}

#[test]
fn nerfstudio_round_trips_camera_to_world_in_opengl_axes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("transforms.json");
    let size = ImageSize::new(84, 56).unwrap();
    let frames: Vec<NerfstudioFrame> = (0..4)
        .map(|i| NerfstudioFrame {
            file_path: format!("images/{i:03}_0.png"),
            size,
            intrinsics: intrinsics(i),
            world_from_camera: pose(i),
        })
        .collect();
    write_transforms(&path, &frames).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    // OpenGL axes: the matrix's third column is the camera's back axis, minus the OpenCV forward axis.
    let m = &json["frames"][1]["transform_matrix"];
    let forward = pose(1).transform_vector(DVec3::Z);
    for r in 0..3 {
        assert!((m[r][2].as_f64().unwrap() + forward[r]).abs() < 1e-12);
        assert!((m[r][3].as_f64().unwrap() - pose(1).translation()[r]).abs() < 1e-12);
    }
    assert_eq!(json["frames"][1]["w"], 84);
    assert_eq!(json["frames"][1]["fl_x"].as_f64().unwrap(), intrinsics(1).fx);
    let back = read_transforms(&path).unwrap();
    assert_eq!(back.len(), 4);
    for (a, b) in frames.iter().zip(&back) {
        assert_eq!((&a.file_path, a.size, a.intrinsics), (&b.file_path, b.size, b.intrinsics));
        assert!(a.world_from_camera.max_abs_difference(&b.world_from_camera) < 1e-6);
    }
}

#[test]
fn camera_json_states_its_convention_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cameras.json");
    let size = ImageSize::new(84, 56).unwrap();
    let records: Vec<CameraRecord> = (0..3)
        .map(|i| CameraRecord {
            name: format!("{i:03}_0"),
            frame: i,
            camera: 0,
            time_s: i as f64 * 0.1,
            size,
            intrinsics: intrinsics(i),
            world_from_camera: pose(i),
        })
        .collect();
    let convention = Convention::opencv("the first input view's camera frame");
    write_cameras_json(&path, &convention, &records).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert!(json["convention"]["axes"].as_str().unwrap().contains("OpenCV"));
    let (convention_back, back) = read_cameras_json(&path).unwrap();
    assert_eq!(convention_back, convention);
    for (a, b) in records.iter().zip(&back) {
        assert_eq!((&a.name, a.frame, a.size, a.intrinsics), (&b.name, b.frame, b.size, b.intrinsics));
        assert!(a.world_from_camera.max_abs_difference(&b.world_from_camera) < 1e-6);
    }
    // A file whose two matrices disagree is rejected.
    let mut json = json;
    json["views"][0]["camera_from_world"][0][3] = serde_json::json!(99.0);
    std::fs::write(&path, serde_json::to_string(&json).unwrap()).unwrap();
    let error = read_cameras_json(&path).unwrap_err().to_string();
    assert!(error.contains("cameras.json") && error.contains("inverse"), "{error}");
}

#[test]
fn depth_round_trips_through_npy_and_png16() {
    let dir = tempfile::tempdir().unwrap();
    let size = ImageSize::new(13, 7).unwrap();
    let mut r = noise(3);
    let mut depth: Vec<f32> = (0..size.area()).map(|_| 0.5 + r() * 80.0).collect();
    depth[4] = f32::NAN;
    depth[5] = -1.0;
    let npy = dir.path().join("d.npy");
    write_depth_npy(&npy, size, &depth).unwrap();
    let (size_back, back) = read_depth_npy(&npy).unwrap();
    assert_eq!(size_back, size);
    assert!(back.iter().zip(&depth).all(|(a, b)| a == b || (a.is_nan() && b.is_nan())));

    let png = dir.path().join("d.png");
    let max = depth.iter().copied().filter(|d| d.is_finite()).fold(0.0f32, f32::max);
    let scale = scale_for(max);
    write_depth_png16(&png, size, &depth, scale).unwrap();
    assert!(dir.path().join("d.json").is_file());
    let (size_back, back, meta) = read_depth_png16(&png).unwrap();
    assert_eq!(size_back, size);
    assert_eq!(meta.scale, scale);
    for (i, (a, b)) in back.iter().zip(&depth).enumerate() {
        if i == 4 || i == 5 {
            assert_eq!(*a, 0.0, "invalid depth is stored as 0");
        } else {
            // Half a quantisation step, plus float32 rounding of values up to 80.
            assert!(((a - b).abs() as f64) <= scale / 2.0 + 2e-5, "pixel {i}: {a} vs {b}");
        }
    }
    assert!(write_depth_npy(&npy, size, &depth[1..]).is_err());
}

#[test]
fn masks_round_trip_within_quantisation() {
    let dir = tempfile::tempdir().unwrap();
    let size = ImageSize::new(5, 3).unwrap();
    let p: Vec<f32> = (0..15).map(|i| i as f32 / 14.0).collect();
    write_probability_png(&dir.path().join("p.png"), size, &p).unwrap();
    let (s, back) = read_mask_png(&dir.path().join("p.png")).unwrap();
    assert_eq!(s, size);
    assert!(back.iter().zip(&p).all(|(a, b)| (a - b).abs() <= 0.5 / 255.0 + 1e-6));
    let mask: Vec<bool> = (0..15).map(|i| i % 3 == 0).collect();
    write_binary_png(&dir.path().join("m.png"), size, &mask).unwrap();
    let (_, back) = read_mask_png(&dir.path().join("m.png")).unwrap();
    assert!(back.iter().zip(&mask).all(|(a, &m)| *a == if m { 1.0 } else { 0.0 }));
}
