//! Argoverse 2 sensor logs (Feather tables, JPEG images) into drivestudio's Argoverse 2 scene export.
//!
//! - [`tables`]: calibration, ego poses and annotations, checked row by row.
//! - [`log`]: one log into one scene folder.

pub mod log;
pub mod tables;

pub use log::{LogSummary, convert_log};
