//! VGGT's camera encoding `absT_quaR_FoV`, the camera head's output.

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::{CameraFromWorld, GeomError, ImageSize, PinholeIntrinsics, QuatXyzw};

/// The nine numbers VGGT's camera head predicts per frame, in this order:
/// `[tx, ty, tz, qx, qy, qz, qw, fov_h, fov_w]`.
///
/// `t` and `q` are the translation and rotation of the camera-from-world extrinsic `[R | t]` (OpenCV axes);
/// the quaternion is scalar-last and, when encoded from a matrix, has a non-negative scalar part. Fields of view
/// are in radians. Decoding puts the principal point at the image centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseEncoding {
    pub translation: [f64; 3],
    pub rotation: QuatXyzw,
    pub fov_h: f64,
    pub fov_w: f64,
}

impl PoseEncoding {
    /// Encodes extrinsics and intrinsics of an image of `size` (the principal point is not encoded).
    pub fn encode(camera_from_world: &CameraFromWorld, intrinsics: &PinholeIntrinsics, size: ImageSize) -> Self {
        let (fov_h, fov_w) = intrinsics.fov(size);
        Self {
            translation: camera_from_world.translation().to_array(),
            rotation: QuatXyzw::from(camera_from_world.rotation()).standardized(),
            fov_h,
            fov_w,
        }
    }

    /// Decodes to extrinsics and intrinsics for an image of `size`. The quaternion need not be normalised
    /// (VGGT's decoding divides by its squared norm); a zero or non-finite encoding is an error.
    pub fn decode(&self, size: ImageSize) -> Result<(CameraFromWorld, PinholeIntrinsics), GeomError> {
        let rotation: DQuat = self.rotation.to_rotation()?;
        let extrinsic =
            CameraFromWorld::from_matrix3_translation(DMat3::from_quat(rotation), DVec3::from_array(self.translation))?;
        let intrinsics = PinholeIntrinsics::from_fov(self.fov_h, self.fov_w, size)?;
        Ok((extrinsic, intrinsics))
    }

    /// The nine numbers in the network's order.
    pub fn to_array(&self) -> [f64; 9] {
        let [tx, ty, tz] = self.translation;
        let [qx, qy, qz, qw] = self.rotation.0;
        [tx, ty, tz, qx, qy, qz, qw, self.fov_h, self.fov_w]
    }

    /// Reads the nine numbers in the network's order.
    pub fn from_array(v: [f64; 9]) -> Self {
        Self { translation: [v[0], v[1], v[2]], rotation: QuatXyzw([v[3], v[4], v[5], v[6]]), fov_h: v[7], fov_w: v[8] }
    }
}
