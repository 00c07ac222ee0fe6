//! Rigid registration of one object's points at two input times: trimmed iterative closest points.
//!
//! The two clouds are different samples of the object's surface (each input view sees its own pixels, and the
//! visible side changes as the object turns), so there are no correspondences to fit: each iteration pairs every
//! source point, moved by the current estimate, with its nearest target point (an R*-tree), keeps the closest
//! fraction of the pairs (the rest are points the other time did not see, or stray pixels of the dynamic mask)
//! and refits the motion to the kept pairs ([`fit_rigid`]). It starts from the predicted motion when the
//! network has one (each point's velocity over the interval, fitted rigidly), else from the shift of the
//! centroids, and is repeated without trimming ([`register`]).
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
        Self { iterations: 50, keep: 0.7, max_points: 1024 }
    }
}

/// A registration's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// Takes the source cloud onto the target cloud.
    pub motion: RigidMotion,
    /// Root mean square distance of the closest `keep` fraction of the (strided) source points to their nearest
    /// target points, in world units.
    pub residual: f64,
}

/// Registers `source` onto `target` starting from `initial` (see the module's doc); `None` when either cloud is
/// empty.
///
/// Trimming lets the parts one time saw and the other did not go unpaired, but it can also drop the few points
/// that pin a slide (a car's rear, against its flank, at a low resolution); so three runs are made, trimmed,
/// untrimmed, and untrimmed from the trimmed result, and the one whose closest `keep` fraction of points lies
/// closest to the target is kept.
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
    let cloud = Cloud { source: &source, tree: RTree::bulk_load(target.iter().map(|p| p.to_array()).collect()) };
    let trimmed = cloud.icp(initial, settings.keep, settings.iterations);
    let candidates =
        [trimmed, cloud.icp(initial, 1.0, settings.iterations), cloud.icp(trimmed, 1.0, settings.iterations)];
    candidates
        .into_iter()
        .map(|motion| Registration { motion, residual: cloud.residual(&motion, settings.keep) })
        .min_by(|a, b| a.residual.total_cmp(&b.residual))
}

/// A source cloud and its target's nearest-neighbour index.
struct Cloud<'a> {
    source: &'a [DVec3],
    tree: RTree<[f64; 3]>,
}

impl Cloud<'_> {
    /// Every source point moved by `motion`, with its nearest target point and their squared distance.
    fn pairs(&self, motion: &RigidMotion) -> Vec<(DVec3, DVec3, f64)> {
        self.source
            .iter()
            .filter_map(|&p| {
                let moved = motion.apply(p);
                let q = DVec3::from_array(*self.tree.nearest_neighbor(moved.to_array())?);
                Some((p, q, moved.distance_squared(q)))
            })
            .collect()
    }

    /// Root mean square distance of the closest `keep` fraction of the moved source points to their nearest
    /// target points.
    fn residual(&self, motion: &RigidMotion, keep: f64) -> f64 {
        let mut squares: Vec<f64> = self.pairs(motion).into_iter().map(|pair| pair.2).collect();
        squares.sort_by(f64::total_cmp);
        let kept = ((squares.len() as f64 * keep.clamp(f64::MIN_POSITIVE, 1.0)).ceil() as usize)
            .clamp(1, squares.len().max(1));
        (squares.iter().take(kept).sum::<f64>() / kept as f64).sqrt()
    }

    /// Iterative closest points from `start`, refitting to the closest `keep` fraction of the pairs, until the
    /// kept pairs' mean square stops falling or `iterations` are done.
    fn icp(&self, start: RigidMotion, keep: f64, iterations: usize) -> RigidMotion {
        let keep = ((self.source.len() as f64 * keep.clamp(f64::MIN_POSITIVE, 1.0)).ceil() as usize).max(1);
        let mut motion = start;
        let mut previous = f64::INFINITY;
        for _ in 0..iterations.max(1) {
            let mut pairs = self.pairs(&motion);
            let keep = keep.min(pairs.len());
            if keep == 0 {
                break;
            }
            pairs.select_nth_unstable_by(keep - 1, |a, b| a.2.total_cmp(&b.2));
            pairs.truncate(keep);
            let mean_square = pairs.iter().map(|pair| pair.2).sum::<f64>() / keep as f64;
            let Some(next) = fit_rigid(pairs.iter().map(|&(p, q, _)| (p, q, 1.0))).filter(RigidMotion::is_finite)
            else {
                break;
            };
            motion = next;
            if mean_square >= previous * (1.0 - 1e-9) {
                break;
            }
            previous = mean_square;
        }
        motion
    }
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
        // Whatever the start, the registration is never worse than it.
        let far = RigidMotion::translation(DVec3::new(0.5, 0.5, 0.0)).after(&truth);
        let from_far = register(&source, &target, far, &RegistrationSettings::default()).unwrap();
        let cloud = Cloud { source: &source, tree: RTree::bulk_load(target.iter().map(|p| p.to_array()).collect()) };
        assert!(from_far.residual <= cloud.residual(&far, RegistrationSettings::default().keep));
    }

    #[test]
    fn empty_clouds_do_not_register() {
        let points = [DVec3::ZERO];
        assert!(register(&[], &points, RigidMotion::IDENTITY, &RegistrationSettings::default()).is_none());
        assert!(register(&points, &[], RigidMotion::IDENTITY, &RegistrationSettings::default()).is_none());
    }
}
