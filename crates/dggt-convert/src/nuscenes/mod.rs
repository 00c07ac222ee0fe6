//! nuScenes (devkit JSON tables, JPEG images, `.pcd.bin` lidar sweeps) into drivestudio's nuScenes scene export.
//!
//! - [`tables`]: the devkit tables, read once per run and indexed by token.
//! - [`scene`]: one row of the `scene` table into one scene folder (key frames, 2 Hz).

pub mod scene;
pub mod tables;

pub use scene::{SceneSummary, convert_scene};
pub use tables::{NuScenesVersion, Tables};
