//! Quaternions with their component order in the type, and shortest-arc SLERP.
//!
//! gsplat and the PLY format store rotations as `w x y z`; VGGT's pose encoding and glam use `x y z w`.
//! Both orders are plain `[f64; 4]` arrays in files and tensors, so each gets its own type here.

use glam::DQuat;
use serde::{Deserialize, Serialize};

use crate::GeomError;

/// A quaternion stored scalar-first: `[w, x, y, z]` (gsplat, PLY `rot_0..rot_3`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct QuatWxyz(pub [f64; 4]);

/// A quaternion stored scalar-last: `[x, y, z, w]` (VGGT's pose encoding, glam).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct QuatXyzw(pub [f64; 4]);

impl From<QuatWxyz> for QuatXyzw {
    fn from(q: QuatWxyz) -> Self {
        let [w, x, y, z] = q.0;
        QuatXyzw([x, y, z, w])
    }
}

impl From<QuatXyzw> for QuatWxyz {
    fn from(q: QuatXyzw) -> Self {
        let [x, y, z, w] = q.0;
        QuatWxyz([w, x, y, z])
    }
}

impl From<DQuat> for QuatXyzw {
    fn from(q: DQuat) -> Self {
        QuatXyzw(q.to_array())
    }
}

impl From<DQuat> for QuatWxyz {
    fn from(q: DQuat) -> Self {
        QuatXyzw::from(q).into()
    }
}

impl QuatXyzw {
    /// The unit rotation this quaternion represents; errors on non-finite or (near-)zero input.
    pub fn to_rotation(self) -> Result<DQuat, GeomError> {
        normalized(DQuat::from_array(self.0), "xyzw quaternion")
    }

    /// The same rotation with a non-negative scalar part (`q` and `-q` are one rotation).
    pub fn standardized(self) -> Self {
        if self.0[3] < 0.0 { QuatXyzw(self.0.map(|v| -v)) } else { self }
    }
}

impl QuatWxyz {
    /// The unit rotation this quaternion represents; errors on non-finite or (near-)zero input.
    pub fn to_rotation(self) -> Result<DQuat, GeomError> {
        QuatXyzw::from(self).to_rotation()
    }
}

/// The unit quaternion of `q`. The components are scaled by their largest magnitude before the norm is taken,
/// so huge inputs do not overflow to infinity; zero (or denormal-small) and non-finite inputs are errors.
pub(crate) fn normalized(q: DQuat, what: &'static str) -> Result<DQuat, GeomError> {
    if !q.is_finite() {
        return Err(GeomError::NonFinite { what });
    }
    let largest = q.to_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if largest < 1e-150 {
        return Err(GeomError::ZeroQuaternion { what });
    }
    let scaled = q / largest;
    Ok(scaled / scaled.length())
}

/// Below this angle between the two rotations (radians, on the 4-sphere) SLERP falls back to normalised
/// linear interpolation: `sin θ` would lose all precision, and the two agree to `O(θ³)`.
const SLERP_LINEAR_THRESHOLD: f64 = 1e-6;

/// Spherical linear interpolation along the shortest arc, `t = 0` giving `a` and `t = 1` giving `b`.
///
/// Inputs need not be normalised. `b` is negated when `a · b < 0`, so antipodal inputs (the same rotation)
/// interpolate to that rotation and rotations 180° apart take one consistent path. Nearly identical inputs use
/// normalised linear interpolation. The result is always a finite unit quaternion for finite non-zero inputs;
/// `t` outside `[0, 1]` extrapolates along the same great circle; a non-finite `t` is an error.
pub fn slerp(a: DQuat, b: DQuat, t: f64) -> Result<DQuat, GeomError> {
    if !t.is_finite() {
        return Err(GeomError::NonFinite { what: "slerp parameter" });
    }
    let a = normalized(a, "slerp start")?;
    let mut b = normalized(b, "slerp end")?;
    let mut cos = a.dot(b);
    if cos < 0.0 {
        b = -b;
        cos = -cos;
    }
    let theta = cos.min(1.0).acos();
    let q = if theta < SLERP_LINEAR_THRESHOLD {
        a * (1.0 - t) + b * t
    } else {
        let sin = theta.sin();
        a * (((1.0 - t) * theta).sin() / sin) + b * ((t * theta).sin() / sin)
    };
    Ok(q.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn order_conversions_round_trip() {
        let q = QuatWxyz([0.5, -0.1, 0.2, 0.8]);
        let x: QuatXyzw = q.into();
        assert_eq!(x.0, [-0.1, 0.2, 0.8, 0.5]);
        assert_eq!(QuatWxyz::from(x), q);
        let r = x.to_rotation().unwrap();
        assert!((r.w - 0.5 / x.0.iter().map(|v| v * v).sum::<f64>().sqrt()).abs() < 1e-12);
    }

    #[test]
    fn huge_quaternions_normalise_without_overflow() {
        let q = QuatWxyz([1e300, 0.0, 0.0, 1e300]).to_rotation().unwrap();
        assert!((q.length() - 1.0).abs() < 1e-12 && (q.w - q.z).abs() < 1e-12);
    }

    #[test]
    fn zero_and_nan_quaternions_are_errors() {
        assert!(matches!(QuatWxyz([0.0; 4]).to_rotation(), Err(GeomError::ZeroQuaternion { .. })));
        assert!(matches!(QuatXyzw([f64::NAN, 0.0, 0.0, 1.0]).to_rotation(), Err(GeomError::NonFinite { .. })));
    }

    #[test]
    fn slerp_handles_antipodal_identical_and_opposite() {
        let a = DQuat::from_rotation_y(0.3);
        let same = slerp(a, -a, 0.37).unwrap();
        assert!(same.dot(a).abs() > 1.0 - 1e-12);
        let tiny = slerp(a, a * DQuat::from_rotation_x(1e-9), 0.5).unwrap();
        assert!(tiny.is_finite() && (tiny.length() - 1.0).abs() < 1e-12);
        let half_turn = slerp(DQuat::IDENTITY, DQuat::from_rotation_z(std::f64::consts::PI), 0.5).unwrap();
        let expected = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        assert!(half_turn.dot(expected).abs() > 1.0 - 1e-12);
        let v = half_turn * DVec3::X;
        assert!(v.abs_diff_eq(DVec3::Y, 1e-12));
    }
}
