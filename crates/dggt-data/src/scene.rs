//! The in-memory description of one driving log: cameras, frames, ground-truth poses and where each view's
//! files are. Pixels are not held here; they are decoded on demand (see [`crate::views`]).
//!
//! Conventions: `world_from_camera` is the ground-truth camera-to-world pose in OpenCV camera axes; for scene
//! exports the world is anchored at the ego pose of the first chosen frame, for KITTI at camera 0 of frame 0.
//! Intrinsics are for the original image size, in the `[0, W] x [0, H]` convention of [`dggt_geom`].

use std::path::PathBuf;

use dggt_geom::{EgoFromCamera, ImageSize, PinholeIntrinsics, WorldFromCamera, WorldFromEgo, WorldFromLogWorld};

use crate::lidar::LidarSweep;
use crate::variant::ExportVariant;

/// Where a scene came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneSource {
    /// The scene-export layout (Waymo, nuScenes, Argoverse 2, synthetic), in one of its variants.
    Export(ExportVariant),
    /// A KITTI odometry sequence.
    Kitti,
}

impl SceneSource {
    /// What `dggt inspect` and the logs call it: `scene export (nuscenes)`, `KITTI odometry`.
    pub fn describe(self) -> String {
        match self {
            Self::Export(variant) => format!("scene export ({variant})"),
            Self::Kitti => "KITTI odometry".into(),
        }
    }
}

/// One camera of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneCamera {
    /// Camera id in the source (Waymo `CameraName - 1` for exports).
    pub id: usize,
    /// Human-readable name (`FRONT`, `FRONT_LEFT`, ... or `cam0`).
    pub name: String,
    /// Original image size.
    pub size: ImageSize,
    /// Intrinsics at the original size.
    pub intrinsics: PinholeIntrinsics,
    /// OpenCV distortion `k1 k2 p1 p2 k3` as stored by the source; images are used as pinhole images.
    pub distortion: [f64; 5],
    /// Mounting on the vehicle (OpenCV camera axes), when the source provides one for the whole log (nuScenes
    /// exports give a camera -> world pose per frame instead).
    pub ego_from_camera: Option<EgoFromCamera>,
}

/// One instant of the log.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneFrame {
    /// Frame index in the source log (file names use it).
    pub index: usize,
    /// Seconds since the first chosen frame.
    pub timestamp: f64,
    /// Ego pose, when the source provides it.
    pub world_from_ego: Option<WorldFromEgo>,
}

/// The files of one (frame, camera) view. Optional files are `None` when the export does not have them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ViewFiles {
    pub image: PathBuf,
    pub sky_mask: Option<PathBuf>,
    pub dynamic_mask: Option<PathBuf>,
    pub fine_dynamic_mask: Option<PathBuf>,
    pub depth_flow: Option<PathBuf>,
}

/// One (frame, camera) view with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Position in [`Scene::frames`].
    pub frame: usize,
    /// Position in [`Scene::cameras`].
    pub camera: usize,
    pub world_from_camera: WorldFromCamera,
    pub files: ViewFiles,
}

/// A driving log, restricted to the chosen cameras and frame range.
#[derive(Debug, Clone)]
pub struct Scene {
    pub name: String,
    pub root: PathBuf,
    pub source: SceneSource,
    pub cameras: Vec<SceneCamera>,
    pub frames: Vec<SceneFrame>,
    /// Frame-major: view `(f, c)` is at `f * cameras.len() + c`.
    pub views: Vec<View>,
    /// Lidar sweep per frame (`lidar/{t:03}.bin`), when present.
    pub lidar: Vec<Option<LidarSweep>>,
    /// The log's world frame (its ego poses and exported scene flow) in the scene's world, which is anchored at
    /// the first chosen frame.
    pub world_from_log: WorldFromLogWorld,
}

impl Scene {
    /// Seconds between consecutive log frames (from the chosen frames' timestamps); `None` with one frame.
    pub fn seconds_per_frame(&self) -> Option<f64> {
        let (first, last) = (self.frames.first()?, self.frames.last()?);
        (last.index > first.index).then(|| (last.timestamp - first.timestamp) / (last.index - first.index) as f64)
    }

    /// The view of frame position `frame` and camera position `camera`.
    pub fn view(&self, frame: usize, camera: usize) -> &View {
        &self.views[frame * self.cameras.len() + camera]
    }

    /// Length of the path driven by camera position `camera` over the chosen frames, in metres.
    pub fn trajectory_length(&self, camera: usize) -> f64 {
        (1..self.frames.len())
            .map(|f| {
                let a = self.view(f - 1, camera).world_from_camera.translation();
                let b = self.view(f, camera).world_from_camera.translation();
                a.distance(b)
            })
            .fold(0.0, |total, step| total + step)
    }

    /// Whether every view has a file of the given kind.
    pub fn all_views_have(&self, has: impl Fn(&ViewFiles) -> bool) -> bool {
        !self.views.is_empty() && self.views.iter().all(|v| has(&v.files))
    }
}
