//! Rigid registration of one object's points at two input times: trimmed iterative closest points.
//!
//! The two clouds are different samples of the object's surface (each input view sees its own pixels, and the
//! visible side changes as the object turns), so there are no correspondences to fit: each iteration pairs every
//! source point, moved by the current estimate, with its nearest target point (an R*-tree), keeps the closest
//! fraction of the pairs (the rest are points the other time did not see, or stray pixels of the dynamic mask)
//! and refits the motion to the kept pairs ([`fit_rigid`]). It starts from the predicted motion when the
//! network has one (each point's velocity over the interval, fitted rigidly), else from the shift of the
//! centroids.
//!
//! A limit of any registration of surfaces alone: an object whose two views share only a plane (a car seen
//! from the front at one time and from the rear at the next, its flank in common) may slide along that plane
//! unnoticed; the predicted motion, where there is one, is what fixes the slide.

use dggt_geom::glam::DVec3;
use rstar::RTree;
use serde::{Deserialize, Serialize};

use crate::rigid::{RigidMotion, fit_rigid};

/// How two clouds are registered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegistrationSettings {
    /// Iterations at most.
    pub iterations: usize,
    /// Fraction of the pairs kept, the closest ones, in `(0, 1]`.
    pub keep: f64,
    /// Points at most per cloud (evenly strided beyond it).
    pub max_points: usize,
}

impl Default for RegistrationSettings {
    fn default() -> Self {
        Self { iterations: 50, keep: 0.7, max_points: 4096 }
    }
}

/// A registration's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// Takes the source cloud onto the target cloud.
    pub motion: RigidMotion,
    /// Root mean square distance of the kept pairs, in world units.
    pub residual: f64,
}

/// Registers `source` onto `target` starting from `initial` (see the module's doc); `None` when either cloud is
/// empty.
pub fn register(
    source: &[DVec3],
    target: &[DVec3],
    initial: RigidMotion,
    settings: &RegistrationSettings,
) -> Option<Registration> {
    let source = strided(source, settings.max_points);
    let target = strided(target, settings.max_points);
    if source.is_empty() || target.is_empty() {
        return None;
    }
    let tree = RTree::bulk_load(target.iter().map(|p| p.to_array()).collect());
    let keep = ((source.len() as f64 * settings.keep.clamp(f64::MIN_POSITIVE, 1.0)).ceil() as usize).max(1);
    let mut motion = initial;
    let mut residual = f64::INFINITY;
    for _ in 0..settings.iterations.max(1) {
        let mut pairs: Vec<(DVec3, DVec3, f64)> = source
            .iter()
            .filter_map(|&p| {
                let nearest = tree.nearest_neighbor(motion.apply(p).to_array())?;
                let q = DVec3::from_array(*nearest);
                Some((p, q, motion.apply(p).distance_squared(q)))
            })
            .collect();
        pairs.select_nth_unstable_by(keep - 1, |a, b| a.2.total_cmp(&b.2));
        pairs.truncate(keep);
        let mean_square = pairs.iter().map(|pair| pair.2).sum::<f64>() / keep as f64;
        let Some(next) = fit_rigid(pairs.iter().map(|&(p, q, _)| (p, q, 1.0))) else { break };
        let converged = mean_square >= residual * residual * (1.0 - 1e-9);
        residual = mean_square.sqrt();
        if !next.is_finite() {
            break;
        }
        motion = next;
        if converged {
            break;
        }
    }
    Some(Registration { motion, residual })
}

/// The starting motion: the points' predicted displacements fitted rigidly when given, else the centroids'
/// shift.
pub fn initial_motion(source: &[DVec3], target: &[DVec3], displacement: Option<&[DVec3]>) -> RigidMotion {
    if let Some(displacement) = displacement {
        let pairs = source.iter().zip(displacement).map(|(&p, &d)| (p, p + d, 1.0));
        if let Some(fit) = fit_rigid(pairs).filter(RigidMotion::is_finite) {
            return fit;
        }
    }
    RigidMotion::translation(centroid(target) - centroid(source))
}

/// Mean of `points` (zero for none).
pub fn centroid(points: &[DVec3]) -> DVec3 {
    if points.is_empty() { DVec3::ZERO } else { points.iter().sum::<DVec3>() / points.len() as f64 }
}

fn strided(points: &[DVec3], max: usize) -> Vec<DVec3> {
    let step = points.len().div_ceil(max.max(1)).max(1);
    points.iter().step_by(step).copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    /// Points on the faces of a car-sized box: a dense surface sample.
    fn box_surface(centre: DVec3, step: f64) -> Vec<DVec3> {
        let half = DVec3::new(2.25, 0.95, 0.75);
        let mut points = Vec::new();
        let count = |extent: f64| (2.0 * extent / step).round() as i32;
        for i in 0..=count(half.x) {
            for j in 0..=count(half.y) {
                for k in 0..=count(half.z) {
                    let p = DVec3::new(i as f64 * step, j as f64 * step, k as f64 * step) - half;
                    let on_face = (p.x.abs() - half.x).abs() < 1e-9
                        || (p.y.abs() - half.y).abs() < 1e-9
                        || (p.z.abs() - half.z).abs() < 1e-9;
                    if on_face {
                        points.push(centre + p);
                    }
                }
            }
        }
        points
    }

    #[test]
    fn a_turning_box_is_registered_from_the_centroid_shift() {
        let source = box_surface(DVec3::new(20.0, 4.0, 0.75), 0.25);
        let truth = RigidMotion { rotation: DQuat::from_rotation_z(0.25), translation: DVec3::new(1.5, 0.4, 0.0) };
        // The target samples the moved surface on another grid offset: no point is paired exactly.
        let target: Vec<DVec3> =
            box_surface(DVec3::new(20.0, 4.0, 0.75), 0.2).iter().map(|&p| truth.apply(p)).collect();
        let start = initial_motion(&source, &target, None);
        let fit = register(&source, &target, start, &RegistrationSettings::default()).unwrap();
        let error = source.iter().map(|&p| fit.motion.apply(p).distance(truth.apply(p))).fold(0.0, f64::max);
        assert!(error < 0.15, "largest point error {error} m, residual {}", fit.residual);
        assert!((fit.motion.angle() - 0.25).abs() < 0.02, "{}", fit.motion.angle());
    }

    #[test]
    fn predicted_displacements_seed_the_registration() {
        let source = box_surface(DVec3::new(0.0, 0.0, 0.75), 0.25);
        let truth = RigidMotion { rotation: DQuat::from_rotation_z(-0.4), translation: DVec3::new(3.0, -1.0, 0.0) };
        let displacement: Vec<DVec3> = source.iter().map(|&p| truth.apply(p) - p).collect();
        let start = initial_motion(&source, &[], Some(&displacement));
        assert!((start.angle() - 0.4).abs() < 1e-9 && start.translation.abs_diff_eq(truth.translation, 1e-9));
        let target: Vec<DVec3> = source.iter().map(|&p| truth.apply(p)).collect();
        let fit = register(&source, &target, start, &RegistrationSettings::default()).unwrap();
        assert!(fit.residual < 1e-9, "{}", fit.residual);
    }

    #[test]
    fn empty_clouds_do_not_register() {
        let points = [DVec3::ZERO];
        assert!(register(&[], &points, RigidMotion::IDENTITY, &RegistrationSettings::default()).is_none());
        assert!(register(&points, &[], RigidMotion::IDENTITY, &RegistrationSettings::default()).is_none());
    }
}
