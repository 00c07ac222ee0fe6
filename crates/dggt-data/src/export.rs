//! Reader of the scene-export layout, in each of its [`ExportVariant`]s: drivestudio's Waymo, nuScenes and
//! Argoverse 2 exports, the STORM / DGGT Waymo export, and what `dggt synth` writes.
//!
//! Conventions of the [`Scene`] it returns, whatever the variant: camera poses are camera -> world in OpenCV
//! axes; the world is the ego frame (forward-left-up) of the first chosen frame — for nuScenes, whose exports
//! have no ego poses, the `LIDAR_TOP` frame turned to forward-left-up ([`variant`](crate::variant)). A camera's
//! pose at frame `t` is `inv(ego[first]) · ego[t] · camera_to_ego` (with Waymo camera axes turned to OpenCV's),
//! or for nuScenes `inv(ego[first]) · camera_to_world[t]`. Timestamps are seconds since the first chosen frame:
//! from `timestamps.txt` when the export has it, else frame index over the frame rate. Distortion coefficients
//! are read and kept, but images are used as pinhole images, as the release does.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use dggt_geom::{Camera, Ego, EgoFromCamera, ImageSize, LogWorld, PinholeIntrinsics, Rigid, Sweep, WaymoCamera, World};
use dggt_geom::{WorldFromCamera, WorldFromLogWorld, axes};

use crate::error::{DataError, Result};
use crate::layout::{DynamicMaskKind, ExportLayout};
use crate::lidar::LidarSweep;
use crate::scene::{Scene, SceneCamera, SceneFrame, SceneSource, View, ViewFiles};
use crate::variant::{
    CameraAxes, CameraMounting, DynamicMaskFolders, ExportVariant, FramePoses, nuscenes_lidar_from_ego,
};
use crate::{images, text};

/// Which part of an export to read, and how.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExportOptions {
    /// Camera ids to read, in this order; `None` reads every camera that has intrinsics.
    pub cameras: Option<Vec<usize>>,
    /// Frame indices to read; `None` reads every frame that has a pose.
    pub frames: Option<Range<usize>>,
    /// Frames per second when the export has no `timestamps.txt`; `None` takes the variant's rate.
    pub frame_rate_hz: Option<f64>,
    /// The layout variant; `None` detects it ([`ExportVariant::detect`]).
    pub variant: Option<ExportVariant>,
}

/// Reads one scene folder of the export layout. Every file is checked: missing or unparsable matrices,
/// non-rigid poses, non-finite numbers, unreadable images and image sizes that disagree with the intrinsics
/// are errors naming the file.
pub fn read_export(root: &Path, options: &ExportOptions) -> Result<Scene> {
    if !root.is_dir() {
        return Err(DataError::malformed(root, "a scene-export folder", "no such directory"));
    }
    let variant = match options.variant {
        Some(variant) => variant,
        None => ExportVariant::detect(root)?,
    };
    let layout = ExportLayout::new(root);
    let camera_ids = match &options.cameras {
        Some(ids) if ids.is_empty() => return Err(DataError::Config("no cameras selected".into())),
        Some(ids) => ids.clone(),
        None => numbered_files(&root.join("intrinsics"), ".txt")?,
    };
    let poses = FramePoseFiles::new(&layout, variant);
    let available = numbered_files(poses.folder(), ".txt")?;
    let frame_indices: Vec<usize> = match &options.frames {
        Some(window) => match crate::window::frames_outside(window, &available) {
            None => window.clone().collect(),
            Some(outside) => return Err(DataError::FramesOutside { root: root.to_owned(), outside }),
        },
        None => available,
    };
    if frame_indices.is_empty() {
        return Err(DataError::malformed(poses.folder(), "at least one frame", "none"));
    }
    let log_from_ego = frame_indices.iter().map(|&t| poses.log_from_ego(t)).collect::<Result<Vec<_>>>()?;
    let anchor: WorldFromLogWorld = log_from_ego[0].inverse().relabel();
    let timestamps = frame_timestamps(&layout, variant, &frame_indices, options.frame_rate_hz)?;
    let frames: Vec<SceneFrame> = frame_indices
        .iter()
        .zip(&log_from_ego)
        .zip(timestamps)
        .map(|((&index, log_from_ego), timestamp)| SceneFrame {
            index,
            timestamp,
            world_from_ego: Some(anchor * *log_from_ego),
        })
        .collect();
    let cameras =
        camera_ids.iter().map(|&id| read_camera(&layout, variant, id, frame_indices[0])).collect::<Result<Vec<_>>>()?;
    let views = read_views(&layout, variant, &frames, &cameras, &anchor)?;
    let lidar = frames.iter().map(|frame| poses.sweep(frame, &anchor, variant)).collect::<Result<Vec<_>>>()?;
    let name = root.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(Scene {
        name,
        root: root.to_owned(),
        source: SceneSource::Export(variant),
        cameras,
        frames,
        views,
        lidar,
        world_from_log: anchor,
    })
}

/// The frame indices of the export at `root` (those with a pose file), sorted, and the folder they are listed in.
pub fn frame_indices(root: &Path, variant: ExportVariant) -> Result<(Vec<usize>, PathBuf)> {
    let layout = ExportLayout::new(root);
    let poses = FramePoseFiles::new(&layout, variant);
    Ok((numbered_files(poses.folder(), ".txt")?, poses.folder().to_owned()))
}

fn read_rigid<To, From>(path: &Path) -> Result<Rigid<To, From>> {
    let rows = text::read_matrix::<4, 4>(path)?;
    Rigid::from_rows(rows).map_err(|e| DataError::geometry(path, e))
}

/// The per-frame pose files of a variant: ego poses, or nuScenes' lidar poses.
struct FramePoseFiles<'a> {
    layout: &'a ExportLayout,
    kind: FramePoses,
    folder: PathBuf,
}

impl<'a> FramePoseFiles<'a> {
    fn new(layout: &'a ExportLayout, variant: ExportVariant) -> Self {
        let kind = variant.frame_poses();
        let folder = layout.root().join(match kind {
            FramePoses::Ego => "ego_pose",
            FramePoses::Lidar => "lidar_pose",
        });
        Self { layout, kind, folder }
    }

    fn folder(&self) -> &Path {
        &self.folder
    }

    /// The frame's ego in the log's world.
    fn log_from_ego(&self, frame: usize) -> Result<Rigid<LogWorld, Ego>> {
        match self.kind {
            FramePoses::Ego => read_rigid(&self.layout.ego_pose(frame)),
            FramePoses::Lidar => {
                let log_from_lidar: Rigid<LogWorld, Sweep> = read_rigid(&self.layout.lidar_pose(frame))?;
                Ok(log_from_lidar * nuscenes_lidar_from_ego())
            }
        }
    }

    /// The frame's lidar sweep, when the export has one.
    fn sweep(
        &self,
        frame: &SceneFrame,
        anchor: &WorldFromLogWorld,
        variant: ExportVariant,
    ) -> Result<Option<LidarSweep>> {
        let path = self.layout.lidar(frame.index);
        if !path.is_file() {
            return Ok(None);
        }
        let world_from_ego = frame.world_from_ego.expect("exports have frame poses");
        let world_from_sweep = match self.kind {
            FramePoses::Ego => world_from_ego.relabel::<World, Sweep>(),
            FramePoses::Lidar => *anchor * read_rigid::<LogWorld, Sweep>(&self.layout.lidar_pose(frame.index))?,
        };
        Ok(Some(LidarSweep { path, format: variant.lidar_format(), world_from_sweep }))
    }
}

/// Seconds since the first chosen frame, from `timestamps.txt` or the frame rate.
fn frame_timestamps(
    layout: &ExportLayout,
    variant: ExportVariant,
    frames: &[usize],
    frame_rate_hz: Option<f64>,
) -> Result<Vec<f64>> {
    let path = layout.timestamps();
    if path.is_file() {
        return recorded_timestamps(&path, frames);
    }
    let rate = frame_rate_hz.or_else(|| rate_of_folder(layout.root())).unwrap_or(variant.default_frame_rate_hz());
    if !(rate.is_finite() && rate > 0.0) {
        return Err(DataError::Config(format!("frame rate must be positive, got {rate}")));
    }
    Ok(frames.iter().map(|&index| (index - frames[0]) as f64 / rate).collect())
}

/// Reads `timestamps.txt` (`frame seconds` per line): every chosen frame must be listed, times increasing.
fn recorded_timestamps(path: &Path, frames: &[usize]) -> Result<Vec<f64>> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let numbers = text::parse_numbers(path, &text)?;
    if numbers.len() % 2 != 0 {
        return Err(DataError::malformed(path, "lines `frame seconds`", format!("{} numbers", numbers.len())));
    }
    let by_frame: BTreeMap<usize, f64> = numbers.chunks_exact(2).map(|pair| (pair[0] as usize, pair[1])).collect();
    let times = frames
        .iter()
        .map(|index| {
            by_frame
                .get(index)
                .copied()
                .ok_or_else(|| DataError::malformed(path, format!("a time for frame {index}"), "no line for it"))
        })
        .collect::<Result<Vec<f64>>>()?;
    if times.windows(2).any(|pair| pair[1] <= pair[0]) {
        return Err(DataError::malformed(path, "times increasing with the frame index", format!("{times:?}")));
    }
    Ok(times.iter().map(|t| t - times[0]).collect())
}

/// The rate in the name of a `processed_{N}Hz` folder above the scene (drivestudio's interpolated nuScenes).
fn rate_of_folder(root: &Path) -> Option<f64> {
    root.ancestors().find_map(|folder| {
        let name = folder.file_name()?.to_str()?;
        name.strip_prefix("processed_")?.strip_suffix("Hz")?.parse().ok()
    })
}

fn read_camera(layout: &ExportLayout, variant: ExportVariant, id: usize, first_frame: usize) -> Result<SceneCamera> {
    let intrinsics_path = layout.intrinsics(id);
    let values = text::read_numbers(&intrinsics_path, 9)?;
    let intrinsics = PinholeIntrinsics::new(values[0], values[1], values[2], values[3])
        .map_err(|e| DataError::geometry(&intrinsics_path, e))?;
    let ego_from_camera = match variant.camera_mounting() {
        CameraMounting::FixedOnEgo => Some(read_mounting(&layout.extrinsics(id), variant.camera_axes())?),
        CameraMounting::PerFrameInWorld => None,
    };
    let image_path = layout.image(first_frame, id);
    let size = images::read_size(&image_path)?;
    check_principal_point(&intrinsics_path, &image_path, &intrinsics, size)?;
    Ok(SceneCamera {
        id,
        name: variant.camera_name(id),
        size,
        intrinsics,
        distortion: [values[4], values[5], values[6], values[7], values[8]],
        ego_from_camera,
    })
}

/// A camera -> ego matrix in the variant's camera axes, as an OpenCV camera's mounting.
fn read_mounting(path: &Path, camera_axes: CameraAxes) -> Result<EgoFromCamera> {
    Ok(match camera_axes {
        CameraAxes::Waymo => axes::ego_from_opencv_camera(&read_rigid::<Ego, WaymoCamera>(path)?),
        CameraAxes::OpenCv => read_rigid::<Ego, Camera>(path)?,
    })
}

/// Every (frame, camera) view, frame-major, with its pose and files.
fn read_views(
    layout: &ExportLayout,
    variant: ExportVariant,
    frames: &[SceneFrame],
    cameras: &[SceneCamera],
    anchor: &WorldFromLogWorld,
) -> Result<Vec<View>> {
    let optional = OptionalFolders::detect(layout.root(), variant);
    let mut views = Vec::with_capacity(frames.len() * cameras.len());
    for (f, frame) in frames.iter().enumerate() {
        for (c, camera) in cameras.iter().enumerate() {
            let files = optional.view_files(layout, frame.index, camera.id)?;
            let size = images::read_size(&files.image)?;
            images::expect_size(&files.image, size, camera.size)?;
            let world_from_camera: WorldFromCamera = match camera.ego_from_camera {
                Some(ego_from_camera) => frame.world_from_ego.expect("exports have frame poses") * ego_from_camera,
                None => *anchor * read_rigid::<LogWorld, Camera>(&layout.extrinsics_at(frame.index, camera.id))?,
            };
            views.push(View { frame: f, camera: c, world_from_camera, files });
        }
    }
    Ok(views)
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
    dynamic: Option<DynamicMaskFolders>,
    fine_dynamic: bool,
    depth_flow: bool,
}

impl OptionalFolders {
    fn detect(root: &Path, variant: ExportVariant) -> Self {
        let dynamic = match variant.dynamic_masks() {
            DynamicMaskFolders::PerClass => root.join("dynamic_masks/all").is_dir(),
            DynamicMaskFolders::Flat => root.join("dynamic_masks").is_dir(),
        };
        Self {
            sky: root.join("sky_masks").is_dir(),
            dynamic: dynamic.then_some(variant.dynamic_masks()),
            fine_dynamic: root.join("fine_dynamic_masks/all").is_dir(),
            depth_flow: root.join("depth_flows_4").is_dir(),
        }
    }

    fn dynamic_mask(&self, layout: &ExportLayout, frame: usize, camera: usize) -> (bool, PathBuf) {
        match self.dynamic {
            None => (false, PathBuf::new()),
            Some(DynamicMaskFolders::PerClass) => (true, layout.dynamic_mask(DynamicMaskKind::All, frame, camera)),
            Some(DynamicMaskFolders::Flat) => (true, layout.flat_dynamic_mask(frame, camera)),
        }
    }

    fn view_files(&self, layout: &ExportLayout, frame: usize, camera: usize) -> Result<ViewFiles> {
        let required = |present: bool, path: PathBuf| -> Result<Option<PathBuf>> {
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
            dynamic_mask: {
                let (present, path) = self.dynamic_mask(layout, frame, camera);
                required(present, path)?
            },
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
