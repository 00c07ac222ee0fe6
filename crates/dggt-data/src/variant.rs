//! The variants of the scene-export layout that the Waymo, nuScenes and Argoverse 2 converters write, what
//! differs between them, and how to tell them apart on disk.
//!
//! | | cameras | camera mounting | poses | lidar | dynamic masks | rate |
//! |---|---|---|---|---|---|---|
//! | [`Waymo`](ExportVariant::Waymo) (drivestudio) | 5 | `extrinsics/{cam}.txt` camera -> ego, Waymo axes | `ego_pose/` | N x 14, ego frame | `{all,human,vehicle}/` | 10 Hz |
//! | [`WaymoStorm`](ExportVariant::WaymoStorm) (STORM / DGGT) | 5 | same | `ego_pose/` | N x 10, ego frame | flat `{t}_{cam}.png` | 10 Hz |
//! | [`NuScenes`](ExportVariant::NuScenes) | 6 | `extrinsics/{t}_{cam}.txt` camera -> world, OpenCV axes, per frame | `lidar_pose/` = world <- lidar | N x 4, lidar frame | `{all,human,vehicle}/` | 2 Hz keyframes, or the `processed_{N}Hz` folder's rate |
//! | [`Argoverse2`](ExportVariant::Argoverse2) | 7 | `extrinsics/{cam}.txt` camera -> ego, OpenCV axes | `ego_pose/` | N x 4, ego frame | `{all,human,vehicle}/` | 10 Hz |
//!
//! `depth_flows_4/` is optional in every variant: STORM's export has it; `dggt convert --depth-flows boxes` writes
//! it for the Waymo, nuScenes and Argoverse 2 variants, with the flow of returns inside tracked boxes in the log
//! world's axes, metres per second, as [`crate::depth_flow`] reads it (`dggt_convert::depth_flows`).
//!
//! A nuScenes export has no ego poses; its frame's ego is the `LIDAR_TOP` sensor with its axes turned to
//! forward-left-up (ego x = lidar y, ego y = -lidar x, ego z = lidar z), which anchors the scene's world.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use dggt_geom::glam::{DMat3, DVec3};
use dggt_geom::{Ego, Rigid, Sweep};

use crate::error::{DataError, Result};
use crate::lidar::LidarFormat;
use crate::text;

/// A variant of the scene-export layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExportVariant {
    /// drivestudio's Waymo export.
    Waymo,
    /// The STORM / DGGT Waymo export: N x 10 lidar, flat dynamic masks, `depth_flows_4/`.
    WaymoStorm,
    /// drivestudio's nuScenes export (keyframes or interpolated).
    #[serde(rename = "nuscenes")]
    NuScenes,
    /// drivestudio's Argoverse 2 export.
    #[serde(rename = "argoverse2")]
    Argoverse2,
}

/// The axes a variant's camera extrinsics are written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraAxes {
    /// x forward (optical axis), y left, z up.
    Waymo,
    /// x right, y down, z forward.
    OpenCv,
}

/// Where a variant keeps the camera poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraMounting {
    /// `extrinsics/{cam}.txt`: one camera -> ego transform per camera, for every frame.
    FixedOnEgo,
    /// `extrinsics/{t}_{cam}.txt`: camera -> world per frame and camera.
    PerFrameInWorld,
}

/// How a variant stores the dynamic masks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DynamicMaskFolders {
    /// `dynamic_masks/{all,human,vehicle}/{t}_{cam}.png`.
    PerClass,
    /// `dynamic_masks/{t}_{cam}.png`: every moving object.
    Flat,
}

/// What the per-frame pose files hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FramePoses {
    /// `ego_pose/{t}.txt`: world <- ego.
    Ego,
    /// `lidar_pose/{t}.txt`: world <- lidar sensor (nuScenes axes: x right, y forward, z up).
    Lidar,
}

impl ExportVariant {
    pub const ALL: [Self; 4] = [Self::Waymo, Self::WaymoStorm, Self::NuScenes, Self::Argoverse2];

    /// The configuration and command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Waymo => "waymo",
            Self::WaymoStorm => "waymo-storm",
            Self::NuScenes => "nuscenes",
            Self::Argoverse2 => "argoverse2",
        }
    }

    /// Camera names by export camera id.
    pub fn camera_names(self) -> &'static [&'static str] {
        const WAYMO: &[&str] = &["FRONT", "FRONT_LEFT", "FRONT_RIGHT", "SIDE_LEFT", "SIDE_RIGHT"];
        const NUSCENES: &[&str] =
            &["CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK_LEFT", "CAM_BACK_RIGHT", "CAM_BACK"];
        const ARGOVERSE2: &[&str] = &[
            "ring_front_center",
            "ring_front_left",
            "ring_front_right",
            "ring_side_left",
            "ring_side_right",
            "ring_rear_left",
            "ring_rear_right",
        ];
        match self {
            Self::Waymo | Self::WaymoStorm => WAYMO,
            Self::NuScenes => NUSCENES,
            Self::Argoverse2 => ARGOVERSE2,
        }
    }

    /// The name of camera `id`, or `cam{id}` past the dataset's cameras.
    pub fn camera_name(self, id: usize) -> String {
        self.camera_names().get(id).map_or_else(|| format!("cam{id}"), |name| name.to_string())
    }

    /// Frames per second when the export writes no timestamps: the rate its converter samples the log at.
    pub fn default_frame_rate_hz(self) -> f64 {
        match self {
            Self::Waymo | Self::WaymoStorm | Self::Argoverse2 => 10.0,
            Self::NuScenes => 2.0,
        }
    }

    pub fn camera_axes(self) -> CameraAxes {
        match self {
            Self::Waymo | Self::WaymoStorm => CameraAxes::Waymo,
            Self::NuScenes | Self::Argoverse2 => CameraAxes::OpenCv,
        }
    }

    pub fn camera_mounting(self) -> CameraMounting {
        match self {
            Self::NuScenes => CameraMounting::PerFrameInWorld,
            Self::Waymo | Self::WaymoStorm | Self::Argoverse2 => CameraMounting::FixedOnEgo,
        }
    }

    pub fn frame_poses(self) -> FramePoses {
        match self {
            Self::NuScenes => FramePoses::Lidar,
            Self::Waymo | Self::WaymoStorm | Self::Argoverse2 => FramePoses::Ego,
        }
    }

    pub fn dynamic_masks(self) -> DynamicMaskFolders {
        match self {
            Self::WaymoStorm => DynamicMaskFolders::Flat,
            Self::Waymo | Self::NuScenes | Self::Argoverse2 => DynamicMaskFolders::PerClass,
        }
    }

    pub fn lidar_format(self) -> LidarFormat {
        match self {
            Self::Waymo => LidarFormat::Waymo14,
            Self::WaymoStorm => LidarFormat::Storm10,
            Self::NuScenes | Self::Argoverse2 => LidarFormat::XyzIntensity,
        }
    }

    /// Tells the variant of the export at `root` from what is on disk: a `synth.json` naming it, then
    /// `lidar_pose/` without `ego_pose/` (nuScenes), flat dynamic masks or `images_4/` (STORM), and last the axes
    /// of the first camera's extrinsics (Waymo axes: Waymo; OpenCV axes: Argoverse 2).
    pub fn detect(root: &Path) -> Result<Self> {
        if let Some(variant) = synthetic_variant(root)? {
            return Ok(variant);
        }
        if root.join("lidar_pose").is_dir() && !root.join("ego_pose").is_dir() {
            return Ok(Self::NuScenes);
        }
        if has_flat_dynamic_masks(root) || root.join("images_4").is_dir() {
            return Ok(Self::WaymoStorm);
        }
        let extrinsics = first_numbered_file(&root.join("extrinsics"))?;
        let rows = text::read_matrix::<4, 4>(&extrinsics)?;
        match axes_of_mounting(&rows) {
            Some(CameraAxes::Waymo) => Ok(Self::Waymo),
            Some(CameraAxes::OpenCv) => Ok(Self::Argoverse2),
            None => Err(DataError::malformed(
                &extrinsics,
                "a camera -> ego matrix whose up axis tells Waymo camera axes (z up) from OpenCV axes (y down); \
                 name the dataset's layout in the configuration",
                "neither axis points up or down",
            )),
        }
    }
}

/// A nuScenes frame's ego in its lidar sensor's axes: ego x (forward) = lidar y, ego y (left) = -lidar x.
pub fn nuscenes_lidar_from_ego() -> Rigid<Sweep, Ego> {
    let rotation = DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z);
    Rigid::from_matrix3_translation(rotation, DVec3::ZERO).expect("a quarter turn is a rotation")
}

/// Which camera axes a camera -> ego matrix is in: an OpenCV camera's y (down) points to ego -z, a Waymo
/// camera's z (up) to ego +z, whatever the camera's heading.
fn axes_of_mounting(rows: &[[f64; 4]; 4]) -> Option<CameraAxes> {
    const UPRIGHT: f64 = 0.5;
    let ego_z = rows[2];
    if ego_z[1] < -UPRIGHT {
        Some(CameraAxes::OpenCv)
    } else if ego_z[2] > UPRIGHT {
        Some(CameraAxes::Waymo)
    } else {
        None
    }
}

/// The variant named by a synthetic scene's `synth.json` (`"layout"`), if the folder is one.
fn synthetic_variant(root: &Path) -> Result<Option<ExportVariant>> {
    let path = root.join(crate::layout::SYNTH_DESCRIPTION);
    let Ok(bytes) = std::fs::read(&path) else { return Ok(None) };
    #[derive(serde::Deserialize)]
    struct Layout {
        layout: Option<ExportVariant>,
    }
    let described: Layout = serde_json::from_slice(&bytes)
        .map_err(|e| DataError::malformed(&path, "a synthetic scene description", e.to_string()))?;
    Ok(Some(described.layout.unwrap_or(ExportVariant::Waymo)))
}

fn has_flat_dynamic_masks(root: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(root.join("dynamic_masks")) else { return false };
    entries.flatten().any(|entry| entry.file_name().to_string_lossy().ends_with(".png"))
}

fn first_numbered_file(folder: &Path) -> Result<std::path::PathBuf> {
    let entries = std::fs::read_dir(folder).map_err(|e| DataError::io(folder, e))?;
    let mut numbered: Vec<(usize, std::path::PathBuf)> = entries
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            let number = name.strip_suffix(".txt")?.parse().ok()?;
            Some((number, entry.path()))
        })
        .collect();
    numbered.sort();
    numbered
        .into_iter()
        .next()
        .map(|(_, path)| path)
        .ok_or_else(|| DataError::malformed(folder, "camera extrinsics `<cam>.txt`", "none"))
}

impl fmt::Display for ExportVariant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ExportVariant {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|v| v.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|v| v.name()).collect();
            format!("unknown export layout {s:?}; expected one of {}", names.join(", "))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_through_text_and_serde() {
        for variant in ExportVariant::ALL {
            assert_eq!(variant.name().parse::<ExportVariant>().unwrap(), variant);
            let json = serde_json::to_string(&variant).unwrap();
            assert_eq!(json, format!("\"{}\"", variant.name()));
            assert_eq!(serde_json::from_str::<ExportVariant>(&json).unwrap(), variant);
        }
        assert!("waymo_v2".parse::<ExportVariant>().unwrap_err().contains("argoverse2"));
    }

    #[test]
    fn mounting_axes_are_told_by_the_up_axis() {
        let waymo_front = [[1.0, 0.0, 0.0, 1.5], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 2.0], [0.0, 0.0, 0.0, 1.0]];
        // An OpenCV camera looking left: its x (right) is ego forward, y (down) ego -z, z (optical axis) ego +y.
        let opencv_left = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 1.6], [0.0, 0.0, 0.0, 1.0]];
        assert_eq!(axes_of_mounting(&waymo_front), Some(CameraAxes::Waymo));
        assert_eq!(axes_of_mounting(&opencv_left), Some(CameraAxes::OpenCv));
        let looking_down = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        assert_eq!(axes_of_mounting(&looking_down), None);
    }

    #[test]
    fn nuscenes_lidar_axes_put_forward_on_lidar_y() {
        let lidar_from_ego = nuscenes_lidar_from_ego();
        assert!(lidar_from_ego.transform_vector(DVec3::X).abs_diff_eq(DVec3::Y, 1e-15));
        assert!(lidar_from_ego.transform_vector(DVec3::Y).abs_diff_eq(-DVec3::X, 1e-15));
        assert!(lidar_from_ego.transform_vector(DVec3::Z).abs_diff_eq(DVec3::Z, 1e-15));
    }
}
