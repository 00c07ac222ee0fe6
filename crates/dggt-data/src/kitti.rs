//! Reader of KITTI odometry sequences into the same [`Scene`] type as scene exports.
//!
//! A sequence folder holds `image_l/*.png` (or `image_0`/`image_2`), `poses.txt` (one row-major 3x4
//! camera-0 -> world matrix per line, frame 0 = world, OpenCV axes) and `calib.txt` (3x4 projection matrices
//! `P0 ..`, with or without their `P0:` prefixes). The images are rectified, so `K` is the left 3x3 block of the
//! first projection matrix. KITTI records at 10 Hz.

use std::ops::Range;
use std::path::{Path, PathBuf};

use dggt_geom::{PinholeIntrinsics, WorldFromCamera};

use crate::error::{DataError, Result};
use crate::export::check_principal_point;
use crate::scene::{Scene, SceneCamera, SceneFrame, SceneSource, View, ViewFiles};
use crate::{images, text};

/// Image folders tried in order: the left camera of the excerpts, then the KITTI names.
const IMAGE_FOLDERS: [&str; 3] = ["image_l", "image_0", "image_2"];
const FRAME_RATE_HZ: f64 = 10.0;

/// Reads a KITTI odometry sequence, restricted to `frames` when given.
pub fn read_kitti_odometry(root: &Path, frames: Option<Range<usize>>) -> Result<Scene> {
    let image_folder =
        IMAGE_FOLDERS.iter().map(|name| root.join(name)).find(|p| p.is_dir()).ok_or_else(|| {
            DataError::malformed(root, format!("a KITTI sequence with one of {IMAGE_FOLDERS:?}"), "none")
        })?;
    let mut image_paths: Vec<PathBuf> = std::fs::read_dir(&image_folder)
        .map_err(|e| DataError::io(&image_folder, e))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|ext| ext == "png"))
        .collect();
    image_paths.sort();

    let poses_path = root.join("poses.txt");
    let poses = read_poses(&poses_path)?;
    if poses.len() != image_paths.len() {
        return Err(DataError::malformed(
            &poses_path,
            format!("one pose per image ({} images in {})", image_paths.len(), image_folder.display()),
            format!("{} poses", poses.len()),
        ));
    }
    let calib_path = root.join("calib.txt");
    let intrinsics = read_intrinsics(&calib_path)?;
    let size = images::read_size(&image_paths[0])?;
    check_principal_point(&calib_path, &image_paths[0], &intrinsics, size)?;

    let range = frames.unwrap_or(0..poses.len());
    if range.is_empty() || range.end > poses.len() {
        return Err(DataError::Config(format!(
            "frames {range:?} are not inside the {} frames of {}",
            poses.len(),
            root.display()
        )));
    }
    let anchor = poses[range.start].inverse();
    let mut scene_frames = Vec::new();
    let mut views = Vec::new();
    for (f, index) in range.clone().enumerate() {
        let image = image_paths[index].clone();
        images::expect_size(&image, images::read_size(&image)?, size)?;
        scene_frames.push(SceneFrame {
            index,
            timestamp: (index - range.start) as f64 / FRAME_RATE_HZ,
            world_from_ego: None,
        });
        let world_from_camera: WorldFromCamera = (anchor * poses[index]).relabel();
        views.push(View { frame: f, camera: 0, world_from_camera, files: ViewFiles { image, ..Default::default() } });
    }
    let camera =
        SceneCamera { id: 0, name: "cam0".into(), size, intrinsics, distortion: [0.0; 5], ego_from_camera: None };
    let name = root.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(Scene {
        name,
        root: root.to_owned(),
        source: SceneSource::Kitti,
        cameras: vec![camera],
        lidar: vec![None; scene_frames.len()],
        frames: scene_frames,
        views,
        world_from_log: anchor.relabel(),
    })
}

fn read_poses(path: &Path) -> Result<Vec<WorldFromCamera>> {
    let content = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    content
        .lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(i, line)| {
            let line_ref =
                path.with_file_name(format!("{}:{}", path.file_name().unwrap_or_default().to_string_lossy(), i + 1));
            let values = text::parse_numbers(&line_ref, line)?;
            if values.len() != 12 {
                return Err(DataError::malformed(&line_ref, "12 numbers (a 3x4 matrix)", format!("{}", values.len())));
            }
            let rows = std::array::from_fn(|r| std::array::from_fn(|c| values[r * 4 + c]));
            WorldFromCamera::from_rows_3x4(rows).map_err(|e| DataError::geometry(&line_ref, e))
        })
        .collect()
}

fn read_intrinsics(path: &Path) -> Result<PinholeIntrinsics> {
    let content = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let first = content
        .lines()
        .find(|line| !line.trim().is_empty())
        .ok_or_else(|| DataError::malformed(path, "projection matrices P0 ..", "an empty file"))?;
    let numbers = first.split_once(':').map_or(first, |(_, rest)| rest);
    let values = text::parse_numbers(path, numbers)?;
    if values.len() != 12 {
        return Err(DataError::malformed(path, "12 numbers on the P0 line", format!("{}", values.len())));
    }
    PinholeIntrinsics::from_rows([
        [values[0], values[1], values[2]],
        [values[4], values[5], values[6]],
        [values[8], values[9], values[10]],
    ])
    .map_err(|e| DataError::geometry(path, e))
}
