//! Rigid motions of world points, and the least-squares one between paired points.
//!
//! A [`RigidMotion`] maps a world point `x` to `R x + t` (`R` a unit quaternion, `w x y z` when written out):
//! both sides are in the reconstruction's world axes and units. The best motion between paired points is Horn's
//! closed form ([`dggt_geom::horn`]); the translation takes the weighted centroid of one side onto the other's.

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::horn::best_rotation;

/// `x -> rotation · x + translation`, in world axes and units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidMotion {
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl RigidMotion {
    pub const IDENTITY: Self = Self { rotation: DQuat::IDENTITY, translation: DVec3::ZERO };

    /// A pure translation.
    pub fn translation(offset: DVec3) -> Self {
        Self { rotation: DQuat::IDENTITY, translation: offset }
    }

    pub fn apply(&self, point: DVec3) -> DVec3 {
        self.rotation * point + self.translation
    }

    /// `self` after `first`: `x -> self(first(x))`.
    pub fn after(&self, first: &Self) -> Self {
        Self { rotation: self.rotation * first.rotation, translation: self.apply(first.translation) }
    }

    pub fn inverse(&self) -> Self {
        let rotation = self.rotation.inverse();
        Self { rotation, translation: -(rotation * self.translation) }
    }

    /// Rotation angle in radians, in `[0, pi]`.
    pub fn angle(&self) -> f64 {
        2.0 * self.rotation.w.abs().clamp(0.0, 1.0).acos()
    }

    /// The fraction `w` of this motion along its screw: rotation by `w` times its angle about its axis (a line
    /// in space, not through the origin in general) and translation by `w` times its slide along that axis.
    /// `w = 0` is the identity, `w = 1` this motion exactly; a planar turn at a constant rate is followed along
    /// its arc, a pure translation linearly.
    pub fn screw_fraction(&self, w: f64) -> Self {
        if w == 1.0 {
            return *self;
        }
        let screw = self.screw();
        let rotation = DQuat::from_axis_angle(screw.axis, screw.angle * w);
        let slide = screw.axis * (screw.slide * w);
        // Rotation about the line through `centre`: x -> R (x - centre) + centre.
        Self { rotation, translation: screw.centre - rotation * screw.centre + slide }
    }

    /// The velocity of the point at `point` under this motion spread evenly over one unit of time (the screw's
    /// constant twist): `omega x (point - centre) + slide · axis`.
    pub fn screw_velocity(&self, point: DVec3) -> DVec3 {
        let screw = self.screw();
        (screw.axis * screw.angle).cross(point - screw.centre) + screw.axis * screw.slide
    }

    fn screw(&self) -> Screw {
        let (axis, angle) = self.rotation.normalize().to_axis_angle();
        // The shorter way round: angles in (-pi, pi].
        let angle = if angle > std::f64::consts::PI { angle - std::f64::consts::TAU } else { angle };
        if !(angle.abs() > 1e-12) || !axis.is_finite() {
            let length = self.translation.length();
            let axis = if length > 0.0 { self.translation / length } else { DVec3::X };
            return Screw { axis, angle: 0.0, slide: length, centre: DVec3::ZERO };
        }
        let slide = axis.dot(self.translation);
        let across = self.translation - axis * slide;
        // The point of the axis nearest the origin solves (I - R) c = across, c perpendicular to the axis.
        let centre = 0.5 * (across + axis.cross(across) / (angle / 2.0).tan());
        Screw { axis, angle, slide, centre }
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation.is_finite()
    }
}

/// A rigid motion as a rotation by `angle` about the line along `axis` through `centre`, and a slide along it.
struct Screw {
    axis: DVec3,
    angle: f64,
    slide: f64,
    centre: DVec3,
}

/// The rigid motion minimising `sum w_i |R p_i + t - q_i|²` over `(p_i, q_i, w_i)`; `None` when the weights
/// sum to zero (or are not finite). Fewer than three pairs in general position leave the rotation about their
/// line (or all of it) undetermined: any minimiser is returned.
pub fn fit_rigid(pairs: impl IntoIterator<Item = (DVec3, DVec3, f64)> + Clone) -> Option<RigidMotion> {
    let (mut weight, mut source_sum, mut target_sum) = (0.0, DVec3::ZERO, DVec3::ZERO);
    for (p, q, w) in pairs.clone() {
        weight += w;
        source_sum += p * w;
        target_sum += q * w;
    }
    if !(weight > 0.0 && weight.is_finite()) {
        return None;
    }
    let (source_mean, target_mean) = (source_sum / weight, target_sum / weight);
    // Cross-covariance S[a][b] = sum w p'_a q'_b.
    let mut s = [[0.0f64; 3]; 3];
    for (p, q, w) in pairs {
        let (p, q) = ((p - source_mean).to_array(), (q - target_mean).to_array());
        for a in 0..3 {
            for b in 0..3 {
                s[a][b] += w * p[a] * q[b];
            }
        }
    }
    let rotation = best_rotation(&s)?;
    Some(RigidMotion { rotation, translation: target_mean - rotation * source_mean })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn box_corners(size: DVec3, centre: DVec3) -> Vec<DVec3> {
        (0..8)
            .map(|i| {
                let sign = |bit: usize| if i >> bit & 1 == 1 { 0.5 } else { -0.5 };
                centre + size * DVec3::new(sign(0), sign(1), sign(2))
            })
            .collect()
    }

    #[test]
    fn a_rotating_box_is_recovered_from_its_corners() {
        // A 4.5 x 1.9 x 1.5 car box turned 20 degrees about +z around its centre and driven 2 m along x.
        let corners = box_corners(DVec3::new(4.5, 1.9, 1.5), DVec3::new(10.0, 3.0, 0.75));
        let yaw = 20f64.to_radians();
        let centre = DVec3::new(10.0, 3.0, 0.75);
        // By hand: x' = Rz (x - c) + c + (2, 0, 0), so t = c + (2, 0, 0) - Rz c.
        let (sin, cos) = yaw.sin_cos();
        let rz = |p: DVec3| DVec3::new(cos * p.x - sin * p.y, sin * p.x + cos * p.y, p.z);
        let moved: Vec<DVec3> = corners.iter().map(|&p| rz(p - centre) + centre + DVec3::X * 2.0).collect();
        let fit = fit_rigid(corners.iter().zip(&moved).map(|(&p, &q)| (p, q, 1.0))).unwrap();
        assert!((fit.angle() - yaw).abs() < 1e-12, "{}", fit.angle());
        let expected_t = centre + DVec3::X * 2.0 - rz(centre);
        assert!(fit.translation.abs_diff_eq(expected_t, 1e-10), "{} vs {expected_t}", fit.translation);
        for (p, q) in corners.iter().zip(&moved) {
            assert!(fit.apply(*p).abs_diff_eq(*q, 1e-10));
        }
    }

    #[test]
    fn zero_weight_has_no_fit() {
        assert!(fit_rigid([(DVec3::ZERO, DVec3::X, 0.0)]).is_none());
        assert!(fit_rigid(std::iter::empty::<(DVec3, DVec3, f64)>()).is_none());
        assert!(fit_rigid([(DVec3::ZERO, DVec3::X, f64::NAN)]).is_none());
    }

    #[test]
    fn composition_and_inverse_agree() {
        let a = RigidMotion { rotation: DQuat::from_rotation_y(0.3), translation: DVec3::new(1.0, 2.0, 3.0) };
        let b = RigidMotion { rotation: DQuat::from_rotation_x(-1.1), translation: DVec3::new(-4.0, 0.5, 0.0) };
        let p = DVec3::new(0.2, -0.7, 5.0);
        assert!(b.after(&a).apply(p).abs_diff_eq(b.apply(a.apply(p)), 1e-12));
        assert!(a.inverse().apply(a.apply(p)).abs_diff_eq(p, 1e-12));
    }

    #[test]
    fn a_turn_at_a_constant_rate_is_followed_along_its_arc() {
        // A point 10 m from the turn centre (3, 0, 0) turns 0.8 rad about +z and climbs 2 m.
        let centre = DVec3::new(3.0, 0.0, 0.0);
        let at = |w: f64| {
            let angle = 0.8 * w;
            centre + DVec3::new(10.0 * angle.cos(), 10.0 * angle.sin(), 2.0 * w)
        };
        let rotation = DQuat::from_rotation_z(0.8);
        let motion = RigidMotion { rotation, translation: at(1.0) - rotation * at(0.0) };
        assert!(motion.apply(at(0.0)).abs_diff_eq(at(1.0), 1e-12));
        for w in [0.0, 0.25, 0.5, 0.9] {
            let got = motion.screw_fraction(w).apply(at(0.0));
            assert!(got.abs_diff_eq(at(w), 1e-9), "{w}: {got} vs {}", at(w));
        }
        assert_eq!(motion.screw_fraction(1.0), motion);
        let h = 1e-6;
        let numeric = (motion.screw_fraction(0.5 + h).apply(at(0.0)) - at(0.5)) / h;
        assert!(numeric.abs_diff_eq(motion.screw_velocity(at(0.5)), 1e-4), "{numeric}");
        // A translation alone is interpolated linearly.
        let shift = RigidMotion::translation(DVec3::new(4.0, -2.0, 1.0));
        assert!(shift.screw_fraction(0.25).translation.abs_diff_eq(DVec3::new(1.0, -0.5, 0.25), 1e-12));
        assert_eq!(RigidMotion::IDENTITY.screw_fraction(0.5), RigidMotion::IDENTITY);
    }

    proptest! {
        #[test]
        fn any_motion_is_recovered_from_exact_pairs(
            axis in (-1.0f64..1.0, -1.0f64..1.0, 0.1f64..1.0),
            angle in -3.1f64..3.1,
            offset in (-50.0f64..50.0, -50.0f64..50.0, -50.0f64..50.0),
            size in (0.5f64..8.0, 0.5f64..8.0, 0.5f64..8.0),
        ) {
            let rotation = DQuat::from_axis_angle(DVec3::new(axis.0, axis.1, axis.2).normalize(), angle);
            let truth = RigidMotion { rotation, translation: DVec3::new(offset.0, offset.1, offset.2) };
            let points = box_corners(DVec3::new(size.0, size.1, size.2), DVec3::new(offset.2, 1.0, -offset.0));
            let fit = fit_rigid(points.iter().map(|&p| (p, truth.apply(p), 1.0))).unwrap();
            for p in &points {
                prop_assert!(fit.apply(*p).abs_diff_eq(truth.apply(*p), 1e-8));
            }
        }
    }
}
