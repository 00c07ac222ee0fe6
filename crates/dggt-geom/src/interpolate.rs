//! Camera interpolation between two timestamps: linear translation, SLERP rotation, linear intrinsics.

use crate::{GeomError, PinholeIntrinsics, Rigid, WorldFromCamera, slerp};

/// Interpolates a rigid transform: translation linearly, rotation by shortest-arc SLERP. `t = 0` gives `a`,
/// `t = 1` gives `b`; values outside `[0, 1]` extrapolate.
///
/// Which direction is interpolated matters: for cameras, interpolate the *pose* (world-from-camera), whose
/// translation is the camera centre, so that the centre moves on a straight line. [`PosedCamera`] does that.
pub fn interpolate_rigid<To, From>(
    a: &Rigid<To, From>,
    b: &Rigid<To, From>,
    t: f64,
) -> Result<Rigid<To, From>, GeomError> {
    let rotation = slerp(a.rotation(), b.rotation(), t)?;
    let translation = a.translation().lerp(b.translation(), t);
    Rigid::from_rotation_translation(rotation, translation)
}

/// Interpolates every intrinsic parameter linearly.
pub fn interpolate_intrinsics(a: &PinholeIntrinsics, b: &PinholeIntrinsics, t: f64) -> PinholeIntrinsics {
    let lerp = |x: f64, y: f64| x + (y - x) * t;
    PinholeIntrinsics { fx: lerp(a.fx, b.fx), fy: lerp(a.fy, b.fy), cx: lerp(a.cx, b.cx), cy: lerp(a.cy, b.cy) }
}

/// A camera at one instant: where it is and how it projects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PosedCamera {
    pub world_from_camera: WorldFromCamera,
    pub intrinsics: PinholeIntrinsics,
}

impl PosedCamera {
    /// The camera at time `t` between `a` (at `time_a`) and `b` (at `time_b`). Errors when the two times
    /// coincide or anything is non-finite.
    pub fn interpolate(a: &Self, time_a: f64, b: &Self, time_b: f64, t: f64) -> Result<Self, GeomError> {
        let span = time_b - time_a;
        if !span.is_finite() || !t.is_finite() {
            return Err(GeomError::NonFinite { what: "interpolation timestamps" });
        }
        if span == 0.0 {
            return Ok(*a);
        }
        let s = (t - time_a) / span;
        Ok(Self {
            world_from_camera: interpolate_rigid(&a.world_from_camera, &b.world_from_camera, s)?,
            intrinsics: interpolate_intrinsics(&a.intrinsics, &b.intrinsics, s),
        })
    }
}
