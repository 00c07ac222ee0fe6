//! Opening a log folder whatever its format: a KITTI odometry sequence (it has `poses.txt` and `calib.txt`)
//! or a scene export.

use std::ops::Range;
use std::path::Path;

use crate::error::{DataError, Result};
use crate::export::{ExportOptions, read_export};
use crate::kitti::read_kitti_odometry;
use crate::scene::Scene;

/// Reads the log at `root`, restricted to `frames` and (for exports) `cameras` when given.
pub fn open_scene(root: &Path, frames: Option<Range<usize>>, cameras: Option<Vec<usize>>) -> Result<Scene> {
    if root.join("poses.txt").is_file() && root.join("calib.txt").is_file() {
        if cameras.as_ref().is_some_and(|c| c != &[0]) {
            return Err(DataError::Config(format!("{} is a KITTI sequence with one camera (0)", root.display())));
        }
        return read_kitti_odometry(root, frames);
    }
    read_export(root, &ExportOptions { cameras, frames, frame_rate_hz: None })
}
