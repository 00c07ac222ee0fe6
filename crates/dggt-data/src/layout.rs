//! File names of the scene-export layout (drivestudio / OmniRe), shared by readers and writers.
//!
//! One scene is one folder. Frame indices are zero-padded to three digits; camera ids are the dataset's export
//! ids (Waymo's `CameraName - 1`: 0 FRONT, 1 FRONT_LEFT, 2 FRONT_RIGHT, 3 SIDE_LEFT, 4 SIDE_RIGHT; the names of
//! the others are in [`crate::variant::ExportVariant::camera_names`]). Which of these files a scene has, and what
//! they hold, depends on its [`ExportVariant`](crate::variant::ExportVariant).

use std::path::{Path, PathBuf};

/// The file a generated scene is described in.
pub const SYNTH_DESCRIPTION: &str = "synth.json";

/// Which dynamic-mask folder to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DynamicMaskKind {
    /// `dynamic_masks/all`: every box moving faster than 1 m/s.
    All,
    /// `dynamic_masks/human`.
    Human,
    /// `dynamic_masks/vehicle`.
    Vehicle,
    /// `fine_dynamic_masks/all`: segmentation-refined masks (what DGGT trains on).
    FineAll,
}

impl DynamicMaskKind {
    fn folder(self) -> &'static str {
        match self {
            Self::All => "dynamic_masks/all",
            Self::Human => "dynamic_masks/human",
            Self::Vehicle => "dynamic_masks/vehicle",
            Self::FineAll => "fine_dynamic_masks/all",
        }
    }
}

/// Paths inside one scene folder of the export layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportLayout {
    root: PathBuf,
}

impl ExportLayout {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `images/{t:03}_{cam}.jpg`.
    pub fn image(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("images").join(format!("{frame:03}_{camera}.jpg"))
    }

    /// `intrinsics/{cam}.txt`: fx fy cx cy k1 k2 p1 p2 k3, one per line.
    pub fn intrinsics(&self, camera: usize) -> PathBuf {
        self.root.join("intrinsics").join(format!("{camera}.txt"))
    }

    /// `extrinsics/{cam}.txt`: 4x4 camera -> ego in the sensor's native axes.
    pub fn extrinsics(&self, camera: usize) -> PathBuf {
        self.root.join("extrinsics").join(format!("{camera}.txt"))
    }

    /// `extrinsics/{t:03}_{cam}.txt`: 4x4 camera -> world in OpenCV axes, per frame (nuScenes).
    pub fn extrinsics_at(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("extrinsics").join(format!("{frame:03}_{camera}.txt"))
    }

    /// `lidar_pose/{t:03}.txt`: 4x4 lidar sensor -> world (nuScenes, which has no ego poses).
    pub fn lidar_pose(&self, frame: usize) -> PathBuf {
        self.root.join("lidar_pose").join(format!("{frame:03}.txt"))
    }

    /// `timestamps.txt`: one line `frame seconds` per frame, when the converter knew the log's times.
    pub fn timestamps(&self) -> PathBuf {
        self.root.join("timestamps.txt")
    }

    /// `ego_pose/{t:03}.txt`: 4x4 ego -> world.
    pub fn ego_pose(&self, frame: usize) -> PathBuf {
        self.root.join("ego_pose").join(format!("{frame:03}.txt"))
    }

    /// `sky_masks/{t:03}_{cam}.png`: 255 = sky.
    pub fn sky_mask(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("sky_masks").join(format!("{frame:03}_{camera}.png"))
    }

    /// The dynamic mask of `kind`: 255 = dynamic.
    pub fn dynamic_mask(&self, kind: DynamicMaskKind, frame: usize, camera: usize) -> PathBuf {
        self.root.join(kind.folder()).join(format!("{frame:03}_{camera}.png"))
    }

    /// `dynamic_masks/{t:03}_{cam}.png`: the STORM variant's single dynamic mask (255 = moving).
    pub fn flat_dynamic_mask(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("dynamic_masks").join(format!("{frame:03}_{camera}.png"))
    }

    /// `lidar/{t:03}.bin`: float32 rows, [`LidarFormat`](crate::lidar::LidarFormat) by variant.
    pub fn lidar(&self, frame: usize) -> PathBuf {
        self.root.join("lidar").join(format!("{frame:03}.bin"))
    }

    /// `depth_flows_4/{t:03}_{cam}.npy`: (H/4, W/4, 4) float32, depth then scene flow xyz.
    pub fn depth_flow(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("depth_flows_4").join(format!("{frame:03}_{camera}.npy"))
    }

    /// `depth_flows_4/origin.json`: where the maps' scene flow comes from (`{"scene_flow": "tracked_boxes"}`).
    pub fn depth_flow_origin(&self) -> PathBuf {
        self.root.join("depth_flows_4").join("origin.json")
    }

    /// `synth.json`: a generated scene's description (`dggt synth`).
    pub fn synth_description(&self) -> PathBuf {
        self.root.join(SYNTH_DESCRIPTION)
    }

    /// `instances/instances_info.json`.
    pub fn instances_info(&self) -> PathBuf {
        self.root.join("instances").join("instances_info.json")
    }

    /// `instances/masks/{t:03}_{cam}.png`: 16-bit, each pixel the key + 1 of the instance (of
    /// `instances_info.json`) whose box outline covers it nearest the camera, 0 where none does.
    pub fn instance_mask(&self, frame: usize, camera: usize) -> PathBuf {
        self.root.join("instances").join("masks").join(format!("{frame:03}_{camera}.png"))
    }

    /// `instances/frame_instances.json`.
    pub fn frame_instances(&self) -> PathBuf {
        self.root.join("instances").join("frame_instances.json")
    }
}
