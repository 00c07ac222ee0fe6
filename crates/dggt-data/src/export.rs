//! Reader of the scene-export layout (drivestudio / OmniRe), which Waymo, nuScenes and Argoverse 2 logs are
//! converted to, and which `dggt synth` writes.
//!
//! Conventions on disk (see `formats.md`): `extrinsics/{cam}.txt` is camera -> ego in Waymo camera axes
//! (x forward, y left, z up); `ego_pose/{t}.txt` is ego -> world. The ground-truth pose of camera `c` at frame
//! `t` is `inv(ego[start]) · ego[t] · camera_to_ego · M`, with `M` the Waymo-to-OpenCV change of axes, so the
//! scene's world frame is the ego frame of the first chosen frame. Distortion coefficients are read and kept,
//! but images are used as pinhole images, as the release does.

use std::ops::Range;
use std::path::Path;

use dggt_geom::{EgoFromCamera, ImageSize, PinholeIntrinsics, Rigid, World, WorldFromEgo, axes};

use crate::error::{DataError, Result};
use crate::layout::{DynamicMaskKind, ExportLayout};
use crate::scene::{Scene, SceneCamera, SceneFrame, SceneSource, View, ViewFiles};
use crate::{images, text};

/// Waymo camera names by export camera id (`CameraName - 1`).
pub const WAYMO_CAMERA_NAMES: [&str; 5] = ["FRONT", "FRONT_LEFT", "FRONT_RIGHT", "SIDE_LEFT", "SIDE_RIGHT"];

/// Which part of an export to read.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExportOptions {
    /// Camera ids to read, in this order; `None` reads every camera that has intrinsics.
    pub cameras: Option<Vec<usize>>,
    /// Frame indices to read; `None` reads every frame that has an ego pose.
    pub frames: Option<Range<usize>>,
    /// Frames per second of the log, for timestamps (10 Hz for Waymo and the synthetic scenes).
    pub frame_rate_hz: Option<f64>,
}

/// Reads one scene folder of the export layout. Every file is checked: missing or unparsable matrices,
/// non-rigid poses, non-finite numbers, unreadable images and image sizes that disagree with the intrinsics
/// are errors naming the file.
pub fn read_export(root: &Path, options: &ExportOptions) -> Result<Scene> {
    if !root.is_dir() {
        return Err(DataError::malformed(root, "a scene-export folder", "no such directory"));
    }
    let layout = ExportLayout::new(root);
    let camera_ids = match &options.cameras {
        Some(ids) if ids.is_empty() => return Err(DataError::Config("no cameras selected".into())),
        Some(ids) => ids.clone(),
        None => numbered_files(&root.join("intrinsics"), ".txt")?,
    };
    let frame_indices: Vec<usize> = match &options.frames {
        Some(range) => range.clone().collect(),
        None => numbered_files(&root.join("ego_pose"), ".txt")?,
    };
    if frame_indices.is_empty() {
        return Err(DataError::malformed(&root.join("ego_pose"), "at least one frame", "none"));
    }
    let frame_rate = options.frame_rate_hz.unwrap_or(10.0);
    if !(frame_rate.is_finite() && frame_rate > 0.0) {
        return Err(DataError::Config(format!("frame rate must be positive, got {frame_rate}")));
    }

    let cameras =
        camera_ids.iter().map(|&id| read_camera(&layout, id, frame_indices[0])).collect::<Result<Vec<_>>>()?;

    let ego_poses = frame_indices
        .iter()
        .map(|&t| read_rigid::<World, dggt_geom::Ego>(&layout.ego_pose(t)))
        .collect::<Result<Vec<WorldFromEgo>>>()?;
    let anchor = ego_poses[0].inverse();
    let first = frame_indices[0];
    let frames: Vec<SceneFrame> = frame_indices
        .iter()
        .zip(&ego_poses)
        .map(|(&index, pose)| SceneFrame {
            index,
            timestamp: (index - first) as f64 / frame_rate,
            world_from_ego: Some((anchor * *pose).relabel()),
        })
        .collect();

    let optional = OptionalFolders::detect(root);
    let mut views = Vec::with_capacity(frames.len() * cameras.len());
    for (f, frame) in frames.iter().enumerate() {
        let world_from_ego = frame.world_from_ego.expect("set above");
        for (c, camera) in cameras.iter().enumerate() {
            let files = optional.view_files(&layout, frame.index, camera.id)?;
            let size = images::read_size(&files.image)?;
            images::expect_size(&files.image, size, camera.size)?;
            let ego_from_camera = camera.ego_from_camera.expect("exports have extrinsics");
            views.push(View { frame: f, camera: c, world_from_camera: world_from_ego * ego_from_camera, files });
        }
    }
    let lidar = frames.iter().map(|frame| Some(layout.lidar(frame.index)).filter(|p| p.is_file())).collect();
    let name = root.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(Scene {
        name,
        root: root.to_owned(),
        source: SceneSource::Export,
        cameras,
        frames,
        views,
        lidar,
        world_from_log: anchor.relabel(),
    })
}

fn read_rigid<To, From>(path: &Path) -> Result<Rigid<To, From>> {
    let rows = text::read_matrix::<4, 4>(path)?;
    Rigid::from_rows(rows).map_err(|e| DataError::geometry(path, e))
}

fn read_camera(layout: &ExportLayout, id: usize, first_frame: usize) -> Result<SceneCamera> {
    let intrinsics_path = layout.intrinsics(id);
    let values = text::read_numbers(&intrinsics_path, 9)?;
    let intrinsics = PinholeIntrinsics::new(values[0], values[1], values[2], values[3])
        .map_err(|e| DataError::geometry(&intrinsics_path, e))?;
    let ego_from_waymo_camera = read_rigid::<dggt_geom::Ego, dggt_geom::WaymoCamera>(&layout.extrinsics(id))?;
    let ego_from_camera: EgoFromCamera = axes::ego_from_opencv_camera(&ego_from_waymo_camera);
    let image_path = layout.image(first_frame, id);
    let size = images::read_size(&image_path)?;
    check_principal_point(&intrinsics_path, &image_path, &intrinsics, size)?;
    Ok(SceneCamera {
        id,
        name: WAYMO_CAMERA_NAMES.get(id).map_or_else(|| format!("cam{id}"), |n| n.to_string()),
        size,
        intrinsics,
        distortion: [values[4], values[5], values[6], values[7], values[8]],
        ego_from_camera: Some(ego_from_camera),
    })
}

/// An image whose size puts the principal point outside it does not belong to these intrinsics.
pub(crate) fn check_principal_point(
    intrinsics_path: &Path,
    image_path: &Path,
    k: &PinholeIntrinsics,
    size: ImageSize,
) -> Result<()> {
    if k.cx <= 0.0 || k.cx >= size.width as f64 || k.cy <= 0.0 || k.cy >= size.height as f64 {
        return Err(DataError::malformed(
            intrinsics_path,
            format!("a principal point inside the {size} image {}", image_path.display()),
            format!("cx={} cy={}", k.cx, k.cy),
        ));
    }
    Ok(())
}

/// The optional per-view folders an export has. When a folder exists, every chosen view must have its file.
struct OptionalFolders {
    sky: bool,
    dynamic: bool,
    fine_dynamic: bool,
    depth_flow: bool,
}

impl OptionalFolders {
    fn detect(root: &Path) -> Self {
        Self {
            sky: root.join("sky_masks").is_dir(),
            dynamic: root.join("dynamic_masks/all").is_dir(),
            fine_dynamic: root.join("fine_dynamic_masks/all").is_dir(),
            depth_flow: root.join("depth_flows_4").is_dir(),
        }
    }

    fn view_files(&self, layout: &ExportLayout, frame: usize, camera: usize) -> Result<ViewFiles> {
        let required = |present: bool, path: std::path::PathBuf| -> Result<Option<std::path::PathBuf>> {
            match (present, path.is_file()) {
                (false, _) => Ok(None),
                (true, true) => Ok(Some(path)),
                (true, false) => Err(DataError::malformed(&path, "a file (its folder exists)", "missing")),
            }
        };
        let image = layout.image(frame, camera);
        if !image.is_file() {
            return Err(DataError::malformed(&image, "a camera image", "missing"));
        }
        Ok(ViewFiles {
            image,
            sky_mask: required(self.sky, layout.sky_mask(frame, camera))?,
            dynamic_mask: required(self.dynamic, layout.dynamic_mask(DynamicMaskKind::All, frame, camera))?,
            fine_dynamic_mask: required(
                self.fine_dynamic,
                layout.dynamic_mask(DynamicMaskKind::FineAll, frame, camera),
            )?,
            depth_flow: required(self.depth_flow, layout.depth_flow(frame, camera))?,
        })
    }
}

/// Sorted numeric stems of `folder/{n}{suffix}` files (`0.txt`, `012.txt`).
fn numbered_files(folder: &Path, suffix: &str) -> Result<Vec<usize>> {
    let entries = std::fs::read_dir(folder).map_err(|e| DataError::io(folder, e))?;
    let mut numbers = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| DataError::io(folder, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(n) = name.strip_suffix(suffix).and_then(|stem| stem.parse().ok()) {
            numbers.push(n);
        }
    }
    numbers.sort_unstable();
    if numbers.is_empty() {
        return Err(DataError::malformed(folder, format!("files named <number>{suffix}"), "none"));
    }
    Ok(numbers)
}
