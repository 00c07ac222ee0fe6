//! Waymo Open Dataset v1: `Frame` TFRecords (one per segment) into drivestudio's Waymo scene export.
//!
//! - [`proto`]: the messages, declared by hand with the upstream field numbers.
//! - [`frame`]: a decoded frame checked into calibrations, the pose and the label boxes.
//! - [`lidar`]: range images into the export's N x 14 lidar rows; [`ground`]: their ground flag.
//! - [`segment`]: one segment streamed into one scene folder.

pub mod frame;
pub mod ground;
pub mod lidar;
pub mod proto;
pub mod segment;

pub use segment::{SegmentSummary, WaymoOptions, convert_segment};
