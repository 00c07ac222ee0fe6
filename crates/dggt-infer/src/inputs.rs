//! Finding the input views: either a folder of images (one camera), a folder of per-camera folders, a glob
//! pattern (`frames/*.jpg`: the matching images are one camera; `cams/*`: each matching folder is a camera), or
//! a scene export / KITTI sequence readable by [`dggt_data::open_scene`] (whose poses then serve as ground truth
//! for the report, never as input).
//!
//! Views are ordered frame-major (all cameras of the first frame, then the next frame); view 0 defines the
//! reconstruction's world frame. Folder inputs are taken as 10 Hz: frame `i` is at `i / 10` s. Every view must
//! have the same image size, since the network batches them.

use std::ops::Range;
use std::path::{Path, PathBuf};

use dggt_data::{PlanarImage, Preprocess, images};
use dggt_geom::{ImageSize, PinholeIntrinsics, WorldFromCamera};

use crate::error::InferError;

/// Frame rate assumed for folders of images.
pub const FOLDER_FRAME_RATE_HZ: f64 = 10.0;

const IMAGE_EXTENSIONS: [&str; 4] = ["jpg", "jpeg", "png", "JPG"];

/// One input view.
#[derive(Debug, Clone, PartialEq)]
pub struct InputImage {
    /// `{frame:03}_{camera}`: the stem of every per-view output file.
    pub name: String,
    pub path: PathBuf,
    /// Frame index in the source (file order for folders).
    pub frame: usize,
    /// Position of the camera among the chosen ones.
    pub camera: usize,
    /// Seconds since the first chosen frame.
    pub time_s: f64,
}

/// What the source knows beyond pixels (scene exports only).
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    /// Per view, in view order.
    pub world_from_camera: Vec<WorldFromCamera>,
    /// Per view, at the original size.
    pub intrinsics: Vec<PinholeIntrinsics>,
}

/// The chosen views of a source.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSet {
    pub root: PathBuf,
    /// "scene export (waymo)", "KITTI odometry", "image folder", ...
    pub kind: String,
    pub views: Vec<InputImage>,
    /// Chosen frame indices, ascending.
    pub frames: Vec<usize>,
    /// Names of the chosen cameras.
    pub cameras: Vec<String>,
    /// The common original image size.
    pub size: ImageSize,
    pub ground_truth: Option<GroundTruth>,
}

impl InputSet {
    /// Opens `root`, keeping frame positions `frames` and camera positions (folders) or ids (exports)
    /// `cameras` when given.
    pub fn open(root: &Path, frames: Option<Range<usize>>, cameras: Option<Vec<usize>>) -> Result<Self, InferError> {
        if !root.is_dir() {
            if is_glob_pattern(root) {
                let set = Self::from_rig(root, "image glob", rig_from_glob(root)?, frames, cameras)?;
                set.check_sizes()?;
                return Ok(set);
            }
            return Err(InferError::input(
                root,
                "not a folder (expected a folder of images, a glob pattern or a scene export)",
            ));
        }
        let is_export = root.join("images").is_dir() && root.join("intrinsics").is_dir();
        let is_kitti = root.join("poses.txt").is_file() && root.join("calib.txt").is_file();
        let set = if is_export || is_kitti {
            Self::open_scene(root, frames, cameras)?
        } else {
            Self::open_folder(root, frames, cameras)?
        };
        set.check_sizes()?;
        Ok(set)
    }

    fn open_scene(root: &Path, frames: Option<Range<usize>>, cameras: Option<Vec<usize>>) -> Result<Self, InferError> {
        let scene = dggt_data::open_scene(root, frames, cameras)?;
        if scene.views.is_empty() {
            return Err(InferError::input(root, "no views in the chosen frames and cameras"));
        }
        let mut views = Vec::new();
        let mut truth = GroundTruth { world_from_camera: Vec::new(), intrinsics: Vec::new() };
        for (f, frame) in scene.frames.iter().enumerate() {
            for c in 0..scene.cameras.len() {
                let view = scene.view(f, c);
                views.push(InputImage {
                    name: format!("{:03}_{}", frame.index, scene.cameras[c].id),
                    path: view.files.image.clone(),
                    frame: frame.index,
                    camera: c,
                    time_s: frame.timestamp,
                });
                truth.world_from_camera.push(view.world_from_camera);
                truth.intrinsics.push(scene.cameras[c].intrinsics);
            }
        }
        let size = images::read_size(&views[0].path)?;
        Ok(Self {
            root: root.to_path_buf(),
            kind: scene.source.describe(),
            frames: scene.frames.iter().map(|f| f.index).collect(),
            cameras: scene.cameras.iter().map(|c| c.name.clone()).collect(),
            views,
            size,
            ground_truth: Some(truth),
        })
    }

    fn open_folder(root: &Path, frames: Option<Range<usize>>, cameras: Option<Vec<usize>>) -> Result<Self, InferError> {
        let (files, folders) = list(root)?;
        let rig = if !files.is_empty() {
            if !folders.is_empty() {
                tracing::warn!("{}: using the images directly in it; its sub-folders are ignored", root.display());
            }
            vec![("cam0".into(), files)]
        } else {
            camera_folders(&folders)?
        };
        Self::from_rig(root, "image folder", rig, frames, cameras)
    }

    /// The views of a rig given as (camera name, image files in frame order) per camera.
    fn from_rig(
        root: &Path,
        kind: &'static str,
        mut rig: Vec<(String, Vec<PathBuf>)>,
        frames: Option<Range<usize>>,
        cameras: Option<Vec<usize>>,
    ) -> Result<Self, InferError> {
        if rig.is_empty() {
            return Err(InferError::input(
                root,
                "no images found (expected .jpg/.png files, or one folder of them per camera)",
            ));
        }
        if let Some(chosen) = cameras {
            let mut picked = Vec::new();
            for &c in &chosen {
                let camera = rig.get(c).ok_or_else(|| {
                    InferError::input(root, format!("camera {c} requested but the folder has {}", rig.len()))
                })?;
                picked.push(camera.clone());
            }
            rig = picked;
        }
        let count = rig[0].1.len();
        if let Some((name, files)) = rig.iter().find(|(_, files)| files.len() != count) {
            return Err(InferError::input(
                root.join(name),
                format!(
                    "{} images, but camera {} has {count}: every camera needs one image per frame",
                    files.len(),
                    rig[0].0
                ),
            ));
        }
        let range = frames.unwrap_or(0..count);
        if range.is_empty() {
            return Err(InferError::input(root, format!("no frames in {range:?}")));
        }
        let available: Vec<usize> = (0..count).collect();
        if let Some(outside) = dggt_data::frames_outside(&range, &available) {
            return Err(InferError::input(root, outside.to_string()));
        }
        let mut views = Vec::new();
        for frame in range.clone() {
            for (c, (_, files)) in rig.iter().enumerate() {
                views.push(InputImage {
                    name: format!("{frame:03}_{c}"),
                    path: files[frame].clone(),
                    frame,
                    camera: c,
                    time_s: (frame - range.start) as f64 / FOLDER_FRAME_RATE_HZ,
                });
            }
        }
        let size = images::read_size(&views[0].path)?;
        Ok(Self {
            root: root.to_path_buf(),
            kind: kind.into(),
            frames: range.collect(),
            cameras: rig.into_iter().map(|(name, _)| name).collect(),
            views,
            size,
            ground_truth: None,
        })
    }

    fn check_sizes(&self) -> Result<(), InferError> {
        let first = &self.views[0].path;
        for view in &self.views[1..] {
            let size = images::read_size(&view.path)?;
            if size != self.size {
                return Err(InferError::input(
                    &view.path,
                    format!(
                        "image is {size} but {} is {}: all inputs must have one size (choose cameras of one \
                         size with --cameras)",
                        first.display(),
                        self.size
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Decodes and preprocesses every view; returns the images and the network-resolution size.
    pub fn load(&self, preprocess: &Preprocess) -> Result<(Vec<PlanarImage>, ImageSize), InferError> {
        let plan = preprocess.plan(self.size)?;
        let images = self
            .views
            .iter()
            .map(|view| {
                let rgb = images::read_rgb(&view.path)?;
                plan.image(&rgb).map_err(|e| InferError::input(&view.path, e.to_string()))
            })
            .collect::<Result<Vec<_>, InferError>>()?;
        Ok((images, plan.output))
    }

    /// The fractional source frame at `time_s`: linear between the chosen frames' times, extended linearly
    /// beyond them.
    pub fn frame_at(&self, time_s: f64) -> f64 {
        let mut points: Vec<(f64, f64)> = self.views.iter().map(|v| (v.time_s, v.frame as f64)).collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        points.dedup_by(|a, b| a.0 == b.0);
        match points.as_slice() {
            [] => 0.0,
            [(_, frame)] => *frame,
            _ => {
                let after = points.iter().position(|p| p.0 > time_s).unwrap_or(points.len() - 1).max(1);
                let ((t0, f0), (t1, f1)) = (points[after - 1], points[after]);
                f0 + (time_s - t0) / (t1 - t0) * (f1 - f0)
            }
        }
    }

    /// The distinct input times, ascending.
    pub fn input_times(&self) -> Vec<f64> {
        let mut times: Vec<f64> = self.views.iter().map(|v| v.time_s).collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        times
    }
}

/// Image files and sub-folders of `dir`, each sorted by name.
/// Whether `path` is a glob pattern rather than a path (it has `*`, `?` or `[`).
fn is_glob_pattern(path: &Path) -> bool {
    path.to_string_lossy().contains(['*', '?', '['])
}

/// The rig of a glob pattern: the matching images (sorted) as one camera, or else each matching folder (sorted)
/// as a camera of its own.
fn rig_from_glob(pattern: &Path) -> Result<Vec<(String, Vec<PathBuf>)>, InferError> {
    let text = pattern.to_string_lossy();
    let matches = glob::glob(&text).map_err(|e| InferError::input(pattern, format!("invalid glob pattern: {e}")))?;
    let paths = matches.map(|entry| entry.map_err(|e| InferError::input(pattern, e.to_string())));
    let (files, folders) = images_and_folders(paths)?;
    if !files.is_empty() {
        return Ok(vec![("cam0".into(), files)]);
    }
    camera_folders(&folders)
}

/// One camera per folder (named after it) with the images in it, leaving out folders without images.
fn camera_folders(folders: &[PathBuf]) -> Result<Vec<(String, Vec<PathBuf>)>, InferError> {
    let cameras = folders
        .iter()
        .map(|folder| {
            let name = folder.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            list(folder).map(|(files, _)| (name, files))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(cameras.into_iter().filter(|(_, files)| !files.is_empty()).collect())
}

fn is_image(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| IMAGE_EXTENSIONS.contains(&e))
}

/// The images and the folders directly in `dir`, each sorted by name.
fn list(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>), InferError> {
    let entries = std::fs::read_dir(dir).map_err(|e| InferError::input(dir, e.to_string()))?;
    images_and_folders(entries.map(|entry| entry.map(|e| e.path()).map_err(|e| InferError::input(dir, e.to_string()))))
}

/// Splits `paths` into image files and folders (other files are left out), each sorted by name.
fn images_and_folders(
    paths: impl Iterator<Item = Result<PathBuf, InferError>>,
) -> Result<(Vec<PathBuf>, Vec<PathBuf>), InferError> {
    let (mut files, mut folders) = (Vec::new(), Vec::new());
    for path in paths {
        let path = path?;
        if path.is_dir() {
            folders.push(path);
        } else if is_image(&path) {
            files.push(path);
        }
    }
    files.sort();
    folders.sort();
    Ok((files, folders))
}
