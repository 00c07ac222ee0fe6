//! Similarity alignment of predicted camera centres to reference centres (Umeyama's least-squares similarity:
//! `b ≈ s R a + t`), with the rotation from Horn's quaternion method ([`dggt_geom::horn`]).
//!
//! Predicted poses live in the first input camera's frame and are up to scale, so comparing them with ground
//! truth needs this alignment first. Collinear centres (a straight drive) leave the roll about the line free;
//! any rotation in that family aligns the centres equally well.

use dggt_geom::WorldFromCamera;
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::horn::best_rotation;
use serde::Serialize;

/// `b ≈ scale · rotation · a + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Similarity {
    pub fn apply(&self, a: DVec3) -> DVec3 {
        self.scale * (self.rotation * a) + self.translation
    }
}

/// The least-squares similarity taking `source` onto `target` (same length, at least two points).
pub fn umeyama(source: &[DVec3], target: &[DVec3]) -> Option<Similarity> {
    if source.len() != target.len() || source.len() < 2 {
        return None;
    }
    let n = source.len() as f64;
    let mean_a = source.iter().copied().sum::<DVec3>() / n;
    let mean_b = target.iter().copied().sum::<DVec3>() / n;
    let mut s = [[0.0f64; 3]; 3];
    let mut variance_a = 0.0;
    for (a, b) in source.iter().zip(target) {
        let (a, b) = (*a - mean_a, *b - mean_b);
        variance_a += a.length_squared();
        for (i, row) in s.iter_mut().enumerate() {
            for (j, value) in row.iter_mut().enumerate() {
                *value += a[i] * b[j];
            }
        }
    }
    if variance_a.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let rotation = best_rotation(&s)?;
    let scale =
        source.iter().zip(target).map(|(a, b)| (*b - mean_b).dot(rotation * (*a - mean_a))).sum::<f64>() / variance_a;
    let translation = mean_b - scale * (rotation * mean_a);
    Some(Similarity { scale, rotation, translation })
}

/// How far predicted poses are from reference poses after aligning the camera centres.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseError {
    /// Scale applied to the prediction.
    pub scale: f64,
    /// Root-mean-square distance of aligned centres from the reference centres (reference units).
    pub centre_rmse: f64,
    /// `centre_rmse` over the reference centres' RMS distance from their mean: 0 is perfect, 1 is no better
    /// than putting every camera at the mean.
    pub centre_rmse_relative: f64,
    /// Largest difference of the rotations relative to the first view, degrees.
    pub rotation_max_deg: f64,
    /// Mean difference of the rotations relative to the first view, degrees.
    pub rotation_mean_deg: f64,
}

/// Compares `predicted` with `reference` (same views, same order); `None` with fewer than two views or when
/// the predicted centres coincide.
pub fn pose_error(predicted: &[WorldFromCamera], reference: &[WorldFromCamera]) -> Option<PoseError> {
    let a: Vec<DVec3> = predicted.iter().map(|p| p.translation()).collect();
    let b: Vec<DVec3> = reference.iter().map(|p| p.translation()).collect();
    let sim = umeyama(&a, &b)?;
    let n = b.len() as f64;
    let mean_b = b.iter().copied().sum::<DVec3>() / n;
    let spread = (b.iter().map(|p| (*p - mean_b).length_squared()).sum::<f64>() / n).sqrt();
    let rmse = (a.iter().zip(&b).map(|(a, b)| (sim.apply(*a) - *b).length_squared()).sum::<f64>() / n).sqrt();
    // Rotations relative to the first view: free of the alignment's rotation, which collinear centres leave
    // partly undetermined.
    let (p0, r0) = (predicted[0].rotation_matrix(), reference[0].rotation_matrix());
    let angles: Vec<f64> = predicted
        .iter()
        .zip(reference)
        .map(|(p, r)| {
            let relative_p = p0.transpose() * p.rotation_matrix();
            let relative_r = r0.transpose() * r.rotation_matrix();
            let difference = DQuat::from_mat3(&(relative_r.transpose() * relative_p));
            2.0 * difference.w.abs().clamp(0.0, 1.0).acos().to_degrees()
        })
        .collect();
    Some(PoseError {
        scale: sim.scale,
        centre_rmse: rmse,
        centre_rmse_relative: if spread > 0.0 { rmse / spread } else { f64::NAN },
        rotation_max_deg: angles.iter().copied().fold(0.0, f64::max),
        rotation_mean_deg: angles.iter().sum::<f64>() / n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_similarity() {
        let truth = Similarity {
            scale: 2.5,
            rotation: DQuat::from_euler(dggt_geom::glam::EulerRot::YXZ, 0.7, -0.3, 1.1),
            translation: DVec3::new(3.0, -1.0, 10.0),
        };
        let source: Vec<DVec3> =
            (0..7).map(|i| DVec3::new(i as f64, (i * i) as f64 * 0.1, (i % 3) as f64 - 1.0)).collect();
        let target: Vec<DVec3> = source.iter().map(|&a| truth.apply(a)).collect();
        let found = umeyama(&source, &target).unwrap();
        assert!((found.scale - 2.5).abs() < 1e-9, "{found:?}");
        for v in [DVec3::X, DVec3::Y, DVec3::Z] {
            assert!((found.rotation * v - truth.rotation * v).length() < 1e-9, "{found:?}");
        }
        assert!((found.translation - truth.translation).length() < 1e-9);
        // Collinear points still align exactly.
        let line: Vec<DVec3> = (0..5).map(|i| DVec3::new(0.0, 0.0, i as f64)).collect();
        let moved: Vec<DVec3> = line.iter().map(|&a| truth.apply(a)).collect();
        let found = umeyama(&line, &moved).unwrap();
        assert!(line.iter().zip(&moved).all(|(a, b)| (found.apply(*a) - *b).length() < 1e-9));
        assert!(umeyama(&line[..1], &moved[..1]).is_none());
    }

    #[test]
    fn pose_error_is_zero_for_a_similar_trajectory() {
        let poses: Vec<WorldFromCamera> = (0..5)
            .map(|i| {
                WorldFromCamera::from_rotation_translation(
                    DQuat::from_rotation_y(0.1 * i as f64),
                    DVec3::new(0.3 * i as f64, 0.0, 2.0 * i as f64),
                )
                .unwrap()
            })
            .collect();
        let turn = DQuat::from_rotation_z(0.4);
        let moved: Vec<WorldFromCamera> = poses
            .iter()
            .map(|p| {
                WorldFromCamera::from_rotation_translation(turn * p.rotation(), 0.5 * (turn * p.translation())).unwrap()
            })
            .collect();
        let error = pose_error(&moved, &poses).unwrap();
        assert!((error.scale - 2.0).abs() < 1e-9 && error.centre_rmse < 1e-9, "{error:?}");
        assert!(error.rotation_max_deg < 1e-5, "{error:?}");
        // Centres out of order along the line are no similarity of it.
        let shuffled: Vec<WorldFromCamera> = [0, 3, 1, 4, 2].iter().map(|&i| moved[i]).collect();
        assert!(pose_error(&shuffled, &poses).unwrap().centre_rmse_relative > 0.3);
    }
}
