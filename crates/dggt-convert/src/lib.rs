//! Converters from raw driving datasets into the scene-export layout ([`dggt_data::ExportLayout`]), natively:
//! no Python, no `protoc`, no TensorFlow.
//!
//! - [`tfrecord`]: TFRecord framing with both CRC checks, streamed record by record; [`feather`]: Feather v2
//!   (Arrow IPC) tables.
//! - [`waymo`]: Waymo Open Dataset v1 segments into drivestudio's Waymo export.
//! - [`argoverse2`]: Argoverse 2 sensor logs into drivestudio's Argoverse 2 export.
//! - [`nuscenes`]: nuScenes devkit tables and files into drivestudio's nuScenes export.
//! - [`batch`]: many segments in parallel into numbered scene folders, finished ones skipped when their done
//!   marker records the same conversion.
//! - Shared by the datasets: [`camera`] (projection with lens distortion), [`undistort`] (images resampled to
//!   the pinhole model), [`boxes`] (annotated 3D boxes),
//!   [`tracks`] (each object's boxes over time: its speed, its box at a camera's own time), [`masks`] (dynamic
//!   masks from projected boxes: moving objects' outlines, or drivestudio's rectangles), [`sky`] (approximate sky masks from lidar), [`instances`]
//!   (`instances/`), [`instance_masks`] (which object each pixel shows), [`box_flow`] (scene flow of lidar points from tracked boxes) and [`depth_flows`]
//!   (`depth_flows_4/`: lidar depth and that flow per quarter-resolution cell), [`marker`] (the done marker a finished scene gets, recording what it was converted from).
//!
//! Every error names the file and the record in it ([`ConvertError`]); bad input never panics.

pub mod argoverse2;
pub mod batch;
pub mod box_flow;
pub mod boxes;
pub mod camera;
pub mod depth_flows;
mod error;
pub mod feather;
pub mod instance_masks;
pub mod instances;
pub mod marker;
pub mod masks;
pub mod nuscenes;
pub mod sky;
pub mod tfrecord;
pub mod tracks;
pub mod undistort;
pub mod waymo;

pub use error::{ConvertError, RecordAt, Result};
pub use marker::{DONE_MARKER, DoneMarker, read_done};
