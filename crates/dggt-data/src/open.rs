//! Opening a log folder whatever its format: a KITTI odometry sequence (it has `poses.txt` and `calib.txt`)
//! or a scene export in one of its variants, as named by the configuration or detected.

use std::fmt;
use std::ops::Range;
use std::path::Path;
use std::str::FromStr;

use crate::error::{DataError, Result};
use crate::export::{ExportOptions, read_export};
use crate::kitti::read_kitti_odometry;
use crate::scene::Scene;
use crate::variant::ExportVariant;

/// The format of a dataset's scene folders, as a configuration names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LogLayout {
    /// Tell from the files ([`ExportVariant::detect`], KITTI by `poses.txt` and `calib.txt`).
    #[default]
    Detect,
    Waymo,
    WaymoStorm,
    Nuscenes,
    Argoverse2,
    Kitti,
    /// A `dggt synth` scene, in whichever export variant its `synth.json` names.
    Synthetic,
}

impl LogLayout {
    pub const ALL: [Self; 7] =
        [Self::Detect, Self::Waymo, Self::WaymoStorm, Self::Nuscenes, Self::Argoverse2, Self::Kitti, Self::Synthetic];

    pub fn name(self) -> &'static str {
        match self {
            Self::Detect => "detect",
            Self::Waymo => "waymo",
            Self::WaymoStorm => "waymo-storm",
            Self::Nuscenes => "nuscenes",
            Self::Argoverse2 => "argoverse2",
            Self::Kitti => "kitti",
            Self::Synthetic => "synthetic",
        }
    }

    /// The export variant this layout fixes, if it fixes one.
    fn export_variant(self) -> Option<ExportVariant> {
        match self {
            Self::Waymo => Some(ExportVariant::Waymo),
            Self::WaymoStorm => Some(ExportVariant::WaymoStorm),
            Self::Nuscenes => Some(ExportVariant::NuScenes),
            Self::Argoverse2 => Some(ExportVariant::Argoverse2),
            Self::Detect | Self::Kitti | Self::Synthetic => None,
        }
    }
}

impl From<ExportVariant> for LogLayout {
    fn from(variant: ExportVariant) -> Self {
        match variant {
            ExportVariant::Waymo => Self::Waymo,
            ExportVariant::WaymoStorm => Self::WaymoStorm,
            ExportVariant::NuScenes => Self::Nuscenes,
            ExportVariant::Argoverse2 => Self::Argoverse2,
        }
    }
}

fn is_kitti(root: &Path) -> bool {
    root.join("poses.txt").is_file() && root.join("calib.txt").is_file()
}

/// Reads the log at `root`, restricted to `frames` and (for exports) `cameras` when given, telling its format
/// from its files.
pub fn open_scene(root: &Path, frames: Option<Range<usize>>, cameras: Option<Vec<usize>>) -> Result<Scene> {
    open_scene_as(root, LogLayout::Detect, frames, cameras)
}

/// Reads the log at `root` in the given layout.
pub fn open_scene_as(
    root: &Path,
    layout: LogLayout,
    frames: Option<Range<usize>>,
    cameras: Option<Vec<usize>>,
) -> Result<Scene> {
    let kitti = match layout {
        LogLayout::Kitti => true,
        LogLayout::Detect => is_kitti(root),
        _ => false,
    };
    if kitti {
        if cameras.as_ref().is_some_and(|c| c != &[0]) {
            return Err(DataError::Config(format!("{} is a KITTI sequence with one camera (0)", root.display())));
        }
        return read_kitti_odometry(root, frames);
    }
    let description = root.join(crate::layout::SYNTH_DESCRIPTION);
    if layout == LogLayout::Synthetic && !description.is_file() {
        return Err(DataError::malformed(&description, "a synthetic scene's description", "missing"));
    }
    read_export(root, &ExportOptions { cameras, frames, frame_rate_hz: None, variant: layout.export_variant() })
}

impl fmt::Display for LogLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for LogLayout {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|l| l.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|l| l.name()).collect();
            format!("unknown layout {s:?}; expected one of {}", names.join(", "))
        })
    }
}
