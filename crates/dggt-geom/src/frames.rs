//! Coordinate frames, as zero-sized marker types for [`Rigid`](crate::Rigid).
//!
//! A frame marker carries no data; it only tells the type checker which space a transform maps from and to.

/// A coordinate frame marker.
pub trait Frame {
    /// Human-readable name, used in error messages and debug output.
    const NAME: &'static str;
}

/// The scene's world frame. In scene exports it is anchored at the first ego pose of the chosen frame range
/// (forward-left-up); in network predictions it is the camera frame of the first input image (OpenCV axes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct World;

/// A log's own world frame, where its ego poses (and an export's scene flow) are expressed, before the scene
/// re-anchors them at its first chosen frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogWorld;

/// The ego vehicle's body frame: x forward, y left, z up (Waymo vehicle convention).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ego;

/// A camera in OpenCV axes: x right, y down, z forward (along the optical axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Camera;

/// A Waymo camera in its native axes: x forward (optical axis), y left, z up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WaymoCamera;

/// The frame a lidar sweep's points are stored in: the ego frame (Waymo, Argoverse 2 exports) or the lidar
/// sensor's own (nuScenes exports: x right, y forward, z up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sweep;

impl Frame for World {
    const NAME: &'static str = "world";
}
impl Frame for LogWorld {
    const NAME: &'static str = "log world";
}
impl Frame for Ego {
    const NAME: &'static str = "ego (forward-left-up)";
}
impl Frame for Camera {
    const NAME: &'static str = "camera (OpenCV: x right, y down, z forward)";
}
impl Frame for Sweep {
    const NAME: &'static str = "lidar sweep";
}
impl Frame for WaymoCamera {
    const NAME: &'static str = "Waymo camera (x forward, y left, z up)";
}
