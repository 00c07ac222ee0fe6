//! Rigid transforms that name the frames they connect.

use std::fmt;
use std::marker::PhantomData;
use std::ops::Mul;

use glam::{DMat3, DMat4, DQuat, DVec3};

use crate::GeomError;
use crate::frames::{Camera, Ego, Frame, LogWorld, World};

/// Largest deviation of `RᵀR` from the identity accepted when reading a rotation matrix. Text exports carry
/// 6-9 significant digits; anything worse than this is a corrupt or non-rigid matrix, not rounding.
pub const ORTHONORMALITY_TOLERANCE: f64 = 1e-3;

/// A rotation followed by a translation mapping points expressed in `From` into `To`:
/// `p_to = R · p_from + t`.
///
/// The rotation is kept as a unit quaternion, so a transform read from a slightly non-orthonormal matrix is
/// re-orthonormalised once, on the way in.
pub struct Rigid<To, From> {
    rotation: DQuat,
    translation: DVec3,
    frames: PhantomData<fn(From) -> To>,
}

/// OpenCV extrinsics `[R | t]`: world points into camera coordinates.
pub type CameraFromWorld = Rigid<Camera, World>;
/// A camera's pose: camera coordinates into world points (its translation is the camera centre).
pub type WorldFromCamera = Rigid<World, Camera>;
/// A camera's mounting on the vehicle, in OpenCV camera axes.
pub type EgoFromCamera = Rigid<Ego, Camera>;
/// The vehicle's pose in the world.
pub type WorldFromEgo = Rigid<World, Ego>;
/// The log's world in the scene's world (the inverse of the anchoring ego pose).
pub type WorldFromLogWorld = Rigid<World, LogWorld>;

impl<To, From> Clone for Rigid<To, From> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<To, From> Copy for Rigid<To, From> {}

impl<To, From> PartialEq for Rigid<To, From> {
    fn eq(&self, other: &Self) -> bool {
        self.rotation == other.rotation && self.translation == other.translation
    }
}

impl<To: Frame, From: Frame> fmt::Debug for Rigid<To, From> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Rigid")
            .field("to", &To::NAME)
            .field("from", &From::NAME)
            .field("rotation_xyzw", &self.rotation)
            .field("translation", &self.translation)
            .finish()
    }
}

impl<To, From> Default for Rigid<To, From> {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl<To, From> Rigid<To, From> {
    /// The transform that changes nothing (the two frames coincide).
    pub const IDENTITY: Self = Self { rotation: DQuat::IDENTITY, translation: DVec3::ZERO, frames: PhantomData };

    /// Builds a transform from a rotation quaternion (normalised here) and a translation.
    pub fn from_rotation_translation(rotation: DQuat, translation: DVec3) -> Result<Self, GeomError> {
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(GeomError::NonFinite { what: "rigid transform" });
        }
        let rotation = crate::quaternion::normalized(rotation, "rigid transform rotation")?;
        Ok(Self { rotation, translation, frames: PhantomData })
    }

    /// Builds a transform from a 3x3 rotation matrix, checked to be orthonormal with determinant +1.
    pub fn from_matrix3_translation(rotation: DMat3, translation: DVec3) -> Result<Self, GeomError> {
        if !rotation.is_finite() || !translation.is_finite() {
            return Err(GeomError::NonFinite { what: "rigid transform" });
        }
        let gram = rotation.transpose() * rotation;
        let deviation = (gram - DMat3::IDENTITY).to_cols_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if deviation > ORTHONORMALITY_TOLERANCE {
            return Err(GeomError::NotRigid {
                what: "rotation block",
                detail: format!("RᵀR deviates from the identity by {deviation:.3e}"),
            });
        }
        let det = rotation.determinant();
        if det <= 0.0 {
            return Err(GeomError::NotRigid {
                what: "rotation block",
                detail: format!("determinant is {det:.4}, expected +1 (a reflection or a singular matrix)"),
            });
        }
        Self::from_rotation_translation(DQuat::from_mat3(&rotation), translation)
    }

    /// Reads a homogeneous 4x4 matrix given as rows (`rows[i][j]` is row `i`, column `j`).
    pub fn from_rows(rows: [[f64; 4]; 4]) -> Result<Self, GeomError> {
        if rows.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeomError::NonFinite { what: "4x4 matrix" });
        }
        let bottom = rows[3];
        let bottom_error = (bottom[0].abs()).max(bottom[1].abs()).max(bottom[2].abs()).max((bottom[3] - 1.0).abs());
        if bottom_error > 1e-6 {
            return Err(GeomError::NotRigid {
                what: "4x4 matrix",
                detail: format!("bottom row is {bottom:?}, expected [0, 0, 0, 1]"),
            });
        }
        Self::from_rows_3x4([rows[0], rows[1], rows[2]])
    }

    /// Reads a 3x4 matrix `[R | t]` given as rows (the layout of KITTI poses and VGGT extrinsics).
    pub fn from_rows_3x4(rows: [[f64; 4]; 3]) -> Result<Self, GeomError> {
        let rotation = DMat3::from_cols(
            DVec3::new(rows[0][0], rows[1][0], rows[2][0]),
            DVec3::new(rows[0][1], rows[1][1], rows[2][1]),
            DVec3::new(rows[0][2], rows[1][2], rows[2][2]),
        );
        let translation = DVec3::new(rows[0][3], rows[1][3], rows[2][3]);
        Self::from_matrix3_translation(rotation, translation)
    }

    /// The homogeneous matrix as rows.
    pub fn to_rows(&self) -> [[f64; 4]; 4] {
        let m = self.to_matrix4().transpose();
        [m.x_axis.to_array(), m.y_axis.to_array(), m.z_axis.to_array(), m.w_axis.to_array()]
    }

    /// The homogeneous matrix (glam, column-major storage).
    pub fn to_matrix4(&self) -> DMat4 {
        DMat4::from_rotation_translation(self.rotation, self.translation)
    }

    /// The unit rotation quaternion.
    pub fn rotation(&self) -> DQuat {
        self.rotation
    }

    /// The rotation as a 3x3 matrix.
    pub fn rotation_matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    /// The translation `t` (for a world-from-camera pose: the camera centre in world coordinates).
    pub fn translation(&self) -> DVec3 {
        self.translation
    }

    /// Maps a point from `From` into `To`.
    pub fn transform_point(&self, point: DVec3) -> DVec3 {
        self.rotation * point + self.translation
    }

    /// Maps a direction (no translation) from `From` into `To`.
    pub fn transform_vector(&self, vector: DVec3) -> DVec3 {
        self.rotation * vector
    }

    /// The transform in the opposite direction.
    pub fn inverse(&self) -> Rigid<From, To> {
        let rotation = self.rotation.conjugate();
        Rigid { rotation, translation: -(rotation * self.translation), frames: PhantomData }
    }

    /// Reinterprets the frames without changing the numbers. Only for boundaries where a convention says two
    /// frames coincide (for example: the world of a prediction is the first camera).
    pub fn relabel<NewTo, NewFrom>(self) -> Rigid<NewTo, NewFrom> {
        Rigid { rotation: self.rotation, translation: self.translation, frames: PhantomData }
    }

    /// Homogeneous row-major 3x4 `[R | t]`, as `f32` for tensors.
    pub fn to_rows_3x4_f32(&self) -> [[f32; 4]; 3] {
        let rows = self.to_rows();
        std::array::from_fn(|i| std::array::from_fn(|j| rows[i][j] as f32))
    }

    /// Largest absolute difference between the two homogeneous matrices.
    pub fn max_abs_difference(&self, other: &Self) -> f64 {
        let a = self.to_matrix4().to_cols_array();
        let b = other.to_matrix4().to_cols_array();
        a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
    }
}

impl WorldFromCamera {
    /// This pose expressed in the camera frame of `reference` (`reference⁻¹ · self`), relabelled as a world: the
    /// world of a prediction is its first input camera, so ground-truth poses are compared in that frame.
    pub fn relative_to(&self, reference: &WorldFromCamera) -> WorldFromCamera {
        (reference.inverse() * *self).relabel()
    }
}

impl<A, B, C> Mul<Rigid<B, C>> for Rigid<A, B> {
    type Output = Rigid<A, C>;

    /// `(A ← B) · (B ← C) = (A ← C)`.
    fn mul(self, rhs: Rigid<B, C>) -> Rigid<A, C> {
        Rigid {
            rotation: (self.rotation * rhs.rotation).normalize(),
            translation: self.rotation * rhs.translation + self.translation,
            frames: PhantomData,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn homogeneous(point: DVec3) -> glam::DVec4 {
        point.extend(1.0)
    }

    #[test]
    fn rejects_reflections_scales_and_nan() {
        let reflect = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        assert!(matches!(CameraFromWorld::from_rows(reflect), Err(GeomError::NotRigid { .. })));
        let scaled = [[2.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0], [0.0, 0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        assert!(matches!(CameraFromWorld::from_rows(scaled), Err(GeomError::NotRigid { .. })));
        let mut nan = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        nan[1][3] = f64::NAN;
        assert!(matches!(CameraFromWorld::from_rows(nan), Err(GeomError::NonFinite { .. })));
        let mut bottom = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        bottom[3][0] = 0.5;
        assert!(matches!(CameraFromWorld::from_rows(bottom), Err(GeomError::NotRigid { .. })));
    }

    #[test]
    fn composition_and_inverse_agree_with_matrices() {
        let a =
            WorldFromEgo::from_rotation_translation(DQuat::from_rotation_z(0.3), DVec3::new(10.0, -2.0, 0.5)).unwrap();
        let b = EgoFromCamera::from_rotation_translation(
            DQuat::from_euler(glam::EulerRot::XYZ, 0.1, -0.2, 0.7),
            DVec3::new(1.5, 0.0, 2.0),
        )
        .unwrap();
        let ab: WorldFromCamera = a * b;
        let expected = a.to_matrix4() * b.to_matrix4();
        assert!((ab.to_matrix4() - expected).abs_diff_eq(DMat4::ZERO, 1e-12));
        let identity = ab * ab.inverse();
        assert!(identity.max_abs_difference(&Rigid::IDENTITY) < 1e-12);
        let p = DVec3::new(0.3, -4.0, 7.0);
        let via_matrix = expected * homogeneous(p);
        assert!(ab.transform_point(p).abs_diff_eq(via_matrix.truncate(), 1e-12));
    }

    #[test]
    fn rows_round_trip() {
        let t = CameraFromWorld::from_rotation_translation(
            DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 2.5),
            DVec3::new(-3.0, 4.0, 100.0),
        )
        .unwrap();
        let back = CameraFromWorld::from_rows(t.to_rows()).unwrap();
        assert!(back.max_abs_difference(&t) < 1e-12);
    }
}
