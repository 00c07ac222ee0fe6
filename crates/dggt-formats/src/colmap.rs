//! COLMAP's text model: `cameras.txt` (one `PINHOLE` camera per image, since predicted intrinsics differ from
//! frame to frame), `images.txt` and an empty `points3D.txt`.
//!
//! Convention (COLMAP's): `images.txt` stores the camera-from-world transform (world -> camera, OpenCV axes) as
//! `QW QX QY QZ TX TY TZ`; `PINHOLE` parameters are `fx fy cx cy` in pixels with the image spanning
//! `[0, W] x [0, H]`. Each image line is followed by its (here empty) line of 2D points.

use std::fmt::Write as _;
use std::path::Path;

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics};

use crate::FormatError;

/// One `PINHOLE` camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub size: ImageSize,
    pub intrinsics: PinholeIntrinsics,
}

/// One registered image.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    pub camera_id: u32,
    /// File name relative to the image folder (no spaces).
    pub name: String,
    pub camera_from_world: CameraFromWorld,
}

/// Writes `cameras.txt`, `images.txt` and an empty `points3D.txt` into `dir`.
pub fn write_colmap(dir: &Path, cameras: &[ColmapCamera], images: &[ColmapImage]) -> Result<(), FormatError> {
    if let Some(image) = images.iter().find(|i| i.name.is_empty() || i.name.contains(char::is_whitespace)) {
        return Err(FormatError::invalid(dir, format!("image name {:?} is empty or has white space", image.name)));
    }
    let mut text = String::from("# Camera list with one line of data per camera:\n");
    text.push_str("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[] (PINHOLE: fx, fy, cx, cy in pixels)\n");
    let _ = writeln!(text, "# Number of cameras: {}", cameras.len());
    for c in cameras {
        let k = &c.intrinsics;
        let _ =
            writeln!(text, "{} PINHOLE {} {} {} {} {} {}", c.id, c.size.width, c.size.height, k.fx, k.fy, k.cx, k.cy);
    }
    crate::write_file(&dir.join("cameras.txt"), text.as_bytes())?;

    let mut text = String::from("# Image list with two lines of data per image:\n");
    text.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME (world -> camera, OpenCV axes)\n");
    text.push_str("#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let _ = writeln!(text, "# Number of images: {}, mean observations per image: 0", images.len());
    for image in images {
        let mut q = image.camera_from_world.rotation();
        if q.w < 0.0 {
            q = -q;
        }
        let t = image.camera_from_world.translation();
        let _ = writeln!(
            text,
            "{} {} {} {} {} {} {} {} {} {}\n",
            image.id, q.w, q.x, q.y, q.z, t.x, t.y, t.z, image.camera_id, image.name
        );
    }
    crate::write_file(&dir.join("images.txt"), text.as_bytes())?;

    let text = "# 3D point list with one line of data per point:\n\
                #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                # Number of points: 0, mean track length: 0\n";
    crate::write_file(&dir.join("points3D.txt"), text.as_bytes())
}

fn numbers<T: std::str::FromStr>(path: &Path, line: usize, words: &[&str]) -> Result<Vec<T>, FormatError> {
    words
        .iter()
        .map(|w| w.parse::<T>().map_err(|_| FormatError::malformed(path, format!("a number on line {line}"), *w)))
        .collect()
}

/// Reads `cameras.txt` (`PINHOLE` cameras only).
pub fn read_cameras_txt(path: &Path) -> Result<Vec<ColmapCamera>, FormatError> {
    let text = String::from_utf8(crate::read_file(path)?)
        .map_err(|_| FormatError::malformed(path, "UTF-8 text", "other bytes"))?;
    let mut cameras = Vec::new();
    for (n, line) in text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())) {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != 8 || words[1] != "PINHOLE" {
            return Err(FormatError::malformed(path, format!("`ID PINHOLE W H fx fy cx cy` on line {n}"), line));
        }
        let id = numbers::<u32>(path, n, &words[..1])?[0];
        let size = numbers::<u32>(path, n, &words[2..4])?;
        let k = numbers::<f64>(path, n, &words[4..8])?;
        cameras.push(ColmapCamera {
            id,
            size: ImageSize::new(size[0], size[1]).map_err(|e| FormatError::invalid(path, format!("line {n}: {e}")))?,
            intrinsics: PinholeIntrinsics::new(k[0], k[1], k[2], k[3])
                .map_err(|e| FormatError::invalid(path, format!("line {n}: {e}")))?,
        });
    }
    Ok(cameras)
}

/// Reads `images.txt`; the 2D-point lines are skipped.
pub fn read_images_txt(path: &Path) -> Result<Vec<ColmapImage>, FormatError> {
    let text = String::from_utf8(crate::read_file(path)?)
        .map_err(|_| FormatError::malformed(path, "UTF-8 text", "other bytes"))?;
    let lines: Vec<(usize, &str)> =
        text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.starts_with('#')).collect();
    let mut images = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let (n, line) = lines[i];
        if line.is_empty() && i + 1 == lines.len() {
            break;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != 10 {
            return Err(FormatError::malformed(
                path,
                format!("`IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` on line {n}"),
                line,
            ));
        }
        let ids = numbers::<u32>(path, n, &[words[0], words[8]])?;
        let v = numbers::<f64>(path, n, &words[1..8])?;
        let rotation = DQuat::from_xyzw(v[1], v[2], v[3], v[0]);
        let camera_from_world = CameraFromWorld::from_rotation_translation(rotation, DVec3::new(v[4], v[5], v[6]))
            .map_err(|e| FormatError::invalid(path, format!("line {n}: {e}")))?;
        images.push(ColmapImage { id: ids[0], camera_id: ids[1], name: words[9].to_string(), camera_from_world });
        i += 2;
    }
    Ok(images)
}
