//! nuScenes (devkit JSON tables, JPEG images, `.pcd.bin` lidar sweeps) into drivestudio's nuScenes scene export.
//!
//! - [`tables`]: the devkit tables, read once per run and indexed by token.
//! - [`annotations`]: the annotated boxes of the masked categories, in the global frame.
//! - [`frames`]: which readings and boxes make each exported frame (key frames, or interpolated between them).
//! - [`scene`]: one row of the `scene` table into one scene folder.

pub mod annotations;
pub mod frames;
pub mod scene;
pub mod tables;

pub use frames::FrameRate;
pub use scene::{NuScenesOptions, SceneSummary, convert_scene};
pub use tables::{NuScenesVersion, Tables};
