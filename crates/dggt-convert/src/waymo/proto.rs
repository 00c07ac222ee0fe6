//! The parts of Waymo Open Dataset v1's `Frame` message (`dataset.proto`, `label.proto`) that the converter
//! reads, declared by hand with the upstream field numbers, so that neither `protoc` nor Python is needed.
//! Fields not declared here are skipped by the decoder. Everything is `proto2` `optional`, hence `Option`.
//!
//! Units and frames as the dataset defines them: matrices are row-major 4x4 `double`s; `Frame.pose` and
//! `CameraImage.pose` map vehicle to global coordinates; `CameraCalibration.extrinsic` maps camera to vehicle
//! (camera axes x forward, y left, z up); `LaserCalibration.extrinsic` maps lidar to vehicle; label boxes are in
//! the vehicle frame of `Frame.pose`; `timestamp_micros` is in microseconds, camera times in seconds.

use prost::Message;

#[derive(Clone, PartialEq, Message)]
pub struct Frame {
    #[prost(message, optional, tag = "1")]
    pub context: Option<Context>,
    /// Start of the first top-lidar spin of the frame, µs since the Unix epoch.
    #[prost(int64, optional, tag = "2")]
    pub timestamp_micros: Option<i64>,
    /// Vehicle -> global.
    #[prost(message, optional, tag = "3")]
    pub pose: Option<Transform>,
    #[prost(message, repeated, tag = "4")]
    pub images: Vec<CameraImage>,
    #[prost(message, repeated, tag = "5")]
    pub lasers: Vec<Laser>,
    #[prost(message, repeated, tag = "6")]
    pub laser_labels: Vec<Label>,
    /// `laser_labels` projected into each camera as axis-aligned image boxes (ids `<label id>_<CAMERA>`).
    #[prost(message, repeated, tag = "9")]
    pub projected_lidar_labels: Vec<CameraLabels>,
}

#[derive(Clone, PartialEq, Message)]
pub struct Context {
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    #[prost(message, repeated, tag = "2")]
    pub camera_calibrations: Vec<CameraCalibration>,
    #[prost(message, repeated, tag = "3")]
    pub laser_calibrations: Vec<LaserCalibration>,
}

/// A row-major 4x4 matrix.
#[derive(Clone, PartialEq, Message)]
pub struct Transform {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub transform: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct CameraCalibration {
    /// `CameraName`: FRONT 1, FRONT_LEFT 2, FRONT_RIGHT 3, SIDE_LEFT 4, SIDE_RIGHT 5.
    #[prost(int32, optional, tag = "1")]
    pub name: Option<i32>,
    /// `[f_u, f_v, c_u, c_v, k1, k2, p1, p2, k3]`, pixels and OpenCV distortion.
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub intrinsic: Vec<f64>,
    /// Camera -> vehicle.
    #[prost(message, optional, tag = "3")]
    pub extrinsic: Option<Transform>,
    #[prost(int32, optional, tag = "4")]
    pub width: Option<i32>,
    #[prost(int32, optional, tag = "5")]
    pub height: Option<i32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct LaserCalibration {
    /// `LaserName`: TOP 1, FRONT 2, SIDE_LEFT 3, SIDE_RIGHT 4, REAR 5.
    #[prost(int32, optional, tag = "1")]
    pub name: Option<i32>,
    /// Beam inclinations in radians, lowest beam first; empty when uniform between min and max.
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub beam_inclinations: Vec<f64>,
    #[prost(double, optional, tag = "3")]
    pub beam_inclination_min: Option<f64>,
    #[prost(double, optional, tag = "4")]
    pub beam_inclination_max: Option<f64>,
    /// Lidar -> vehicle.
    #[prost(message, optional, tag = "5")]
    pub extrinsic: Option<Transform>,
}

#[derive(Clone, PartialEq, Message)]
pub struct CameraImage {
    #[prost(int32, optional, tag = "1")]
    pub name: Option<i32>,
    /// The JPEG file, as recorded.
    #[prost(bytes = "vec", optional, tag = "2")]
    pub image: Option<Vec<u8>>,
}

#[derive(Clone, PartialEq, Message)]
pub struct Laser {
    #[prost(int32, optional, tag = "1")]
    pub name: Option<i32>,
    #[prost(message, optional, tag = "2")]
    pub ri_return1: Option<RangeImage>,
    #[prost(message, optional, tag = "3")]
    pub ri_return2: Option<RangeImage>,
}

/// Each field is a zlib-compressed serialised [`MatrixFloat`] (or [`MatrixInt32`]).
#[derive(Clone, PartialEq, Message)]
pub struct RangeImage {
    /// `[H, W, 4]`: range (m), intensity, elongation, is-in-no-label-zone.
    #[prost(bytes = "vec", optional, tag = "2")]
    pub range_image_compressed: Option<Vec<u8>>,
    /// `[H, W, 6]`: roll, pitch, yaw (rad), x, y, z (m): vehicle -> global per pixel. TOP lidar, first return.
    #[prost(bytes = "vec", optional, tag = "4")]
    pub range_image_pose_compressed: Option<Vec<u8>>,
    /// `[H, W, 4]`: vx, vy, vz (m/s), class (-1 no flow label, 0 background, 1 vehicle, 2 pedestrian, 3 sign,
    /// 4 cyclist). Only in the scene-flow release.
    #[prost(bytes = "vec", optional, tag = "5")]
    pub range_image_flow_compressed: Option<Vec<u8>>,
}

#[derive(Clone, PartialEq, Message)]
pub struct MatrixShape {
    #[prost(int32, repeated, tag = "1")]
    pub dims: Vec<i32>,
}

/// Row-major; `data.len()` is the product of `shape.dims`.
#[derive(Clone, PartialEq, Message)]
pub struct MatrixFloat {
    #[prost(float, repeated, tag = "1")]
    pub data: Vec<f32>,
    #[prost(message, optional, tag = "2")]
    pub shape: Option<MatrixShape>,
}

#[derive(Clone, PartialEq, Message)]
pub struct CameraLabels {
    #[prost(int32, optional, tag = "1")]
    pub name: Option<i32>,
    #[prost(message, repeated, tag = "2")]
    pub labels: Vec<Label>,
}

#[derive(Clone, PartialEq, Message)]
pub struct Label {
    #[prost(message, optional, tag = "1")]
    pub r#box: Option<LabelBox>,
    #[prost(message, optional, tag = "2")]
    pub metadata: Option<LabelMetadata>,
    /// `Label.Type`: 0 unknown, 1 vehicle, 2 pedestrian, 3 sign, 4 cyclist.
    #[prost(int32, optional, tag = "3")]
    pub r#type: Option<i32>,
    /// Stable within a segment.
    #[prost(string, optional, tag = "4")]
    pub id: Option<String>,
    #[prost(int32, optional, tag = "7")]
    pub num_lidar_points_in_box: Option<i32>,
    #[prost(int32, optional, tag = "13")]
    pub num_top_lidar_points_in_box: Option<i32>,
}

/// An upright box. For laser labels: centre in metres in the vehicle frame, extents along the box's x
/// (`length`), y (`width`) and z (`height`), `heading` the yaw in radians taking +x to the box's front. For
/// projected labels: centre and extents in pixels.
#[derive(Clone, PartialEq, Message)]
pub struct LabelBox {
    #[prost(double, optional, tag = "1")]
    pub center_x: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub center_y: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub center_z: Option<f64>,
    #[prost(double, optional, tag = "4")]
    pub width: Option<f64>,
    #[prost(double, optional, tag = "5")]
    pub length: Option<f64>,
    #[prost(double, optional, tag = "6")]
    pub height: Option<f64>,
    #[prost(double, optional, tag = "7")]
    pub heading: Option<f64>,
}

/// Box velocity in m/s (horizontal components only are used).
#[derive(Clone, PartialEq, Message)]
pub struct LabelMetadata {
    #[prost(double, optional, tag = "1")]
    pub speed_x: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub speed_y: Option<f64>,
}

/// Decodes one frame record.
pub fn decode_frame(payload: &[u8]) -> Result<Frame, prost::DecodeError> {
    Frame::decode(payload)
}
