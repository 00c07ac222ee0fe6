//! World-space covariance of a Gaussian from its rotation and scales, `Σ = R S Sᵀ Rᵀ`, and its vector-Jacobian
//! product back to the unnormalised `wxyz` quaternion and the scales.
//!
//! Evaluated in `f64` (inputs are `f32`): scales span many orders of magnitude in degenerate scenes, and the
//! projection that follows multiplies `Σ` by large Jacobians.
//!
//! Sanitising: a quaternion with norm below [`QUAT_MIN_NORM`] (in particular all zeros) has no direction to
//! normalise; it is treated as the identity rotation and receives a zero gradient.

use glam::{DMat3, DVec3};

use crate::constants::QUAT_MIN_NORM;

/// `Σ = M Mᵀ` with `M = R(q / |q|) diag(s)`, keeping what the gradient needs.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Covariance {
    /// The normalised quaternion `w x y z` (identity when sanitised).
    unit: [f64; 4],
    /// `|q|` of the input quaternion.
    norm: f64,
    /// Whether the input quaternion was too short and replaced by the identity.
    sanitised: bool,
    rotation: DMat3,
    scale: DVec3,
    /// `M = R diag(s)`, so that `Σ = M Mᵀ`.
    pub factor: DMat3,
    pub sigma: DMat3,
}

impl Covariance {
    pub fn new(q: [f64; 4], scale: [f64; 3]) -> Self {
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let sanitised = norm.is_nan() || norm < QUAT_MIN_NORM;
        let unit = if sanitised { [1.0, 0.0, 0.0, 0.0] } else { q.map(|v| v / norm) };
        let rotation = rotation_matrix(unit);
        let scale = DVec3::from_array(scale);
        let factor = DMat3::from_cols(rotation.x_axis * scale.x, rotation.y_axis * scale.y, rotation.z_axis * scale.z);
        let sigma = factor * factor.transpose();
        Self { unit, norm, sanitised, rotation, scale, factor, sigma }
    }

    /// Given `dL/dΣ`, returns `(dL/dq, dL/ds)` for the unnormalised quaternion `q` (`w x y z`) and the scales.
    pub fn backward(&self, grad_sigma: DMat3) -> ([f64; 4], [f64; 3]) {
        let grad_factor = (grad_sigma + grad_sigma.transpose()) * self.factor;
        let grad_scale = [
            grad_factor.x_axis.dot(self.rotation.x_axis),
            grad_factor.y_axis.dot(self.rotation.y_axis),
            grad_factor.z_axis.dot(self.rotation.z_axis),
        ];
        if self.sanitised {
            return ([0.0; 4], grad_scale);
        }
        let grad_rotation = DMat3::from_cols(
            grad_factor.x_axis * self.scale.x,
            grad_factor.y_axis * self.scale.y,
            grad_factor.z_axis * self.scale.z,
        );
        let grad_unit = rotation_matrix_backward(self.unit, grad_rotation);
        // Jacobian of q / |q|: (I - u uᵀ) / |q|.
        let along: f64 = grad_unit.iter().zip(&self.unit).map(|(g, u)| g * u).sum();
        let grad_quat = std::array::from_fn(|k| (grad_unit[k] - self.unit[k] * along) / self.norm);
        (grad_quat, grad_scale)
    }
}

/// Rotation matrix of a unit quaternion `w x y z`.
fn rotation_matrix([w, x, y, z]: [f64; 4]) -> DMat3 {
    let rows = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ];
    DMat3::from_cols_array_2d(&rows).transpose()
}

/// `dL/du` for `R(u)` given `dL/dR` (the quaternion treated as unconstrained, before normalisation).
fn rotation_matrix_backward([w, x, y, z]: [f64; 4], g: DMat3) -> [f64; 4] {
    // g.col(j)[i] is dL/dR[i][j].
    let at = |i: usize, j: usize| g.col(j)[i];
    let (g00, g01, g02) = (at(0, 0), at(0, 1), at(0, 2));
    let (g10, g11, g12) = (at(1, 0), at(1, 1), at(1, 2));
    let (g20, g21, g22) = (at(2, 0), at(2, 1), at(2, 2));
    [
        2.0 * (x * (g21 - g12) + y * (g02 - g20) + z * (g10 - g01)),
        2.0 * (y * (g01 + g10) + z * (g02 + g20) + w * (g21 - g12)) - 4.0 * x * (g11 + g22),
        2.0 * (x * (g01 + g10) + z * (g12 + g21) + w * (g02 - g20)) - 4.0 * y * (g00 + g22),
        2.0 * (x * (g02 + g20) + y * (g12 + g21) + w * (g10 - g01)) - 4.0 * z * (g00 + g11),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loss(q: [f64; 4], s: [f64; 3], weights: DMat3) -> f64 {
        let sigma = Covariance::new(q, s).sigma;
        (0..3).map(|j| sigma.col(j).dot(weights.col(j))).sum()
    }

    #[test]
    fn rotation_is_orthonormal_and_matches_glam() {
        let q = [0.3f64, -0.5, 0.7, 0.2];
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let u = q.map(|v| v / n);
        let r = rotation_matrix(u);
        let reference = DMat3::from_quat(glam::DQuat::from_xyzw(u[1], u[2], u[3], u[0]));
        assert!(r.abs_diff_eq(reference, 1e-12));
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let q64 = [0.8, -0.4, 1.3, 0.25];
        let s64 = [0.3, 1.7, 0.05];
        let weights = DMat3::from_cols_array(&[0.3, -1.2, 0.7, 0.4, 2.0, -0.1, 0.9, 0.5, -0.6]);
        let (gq, gs) = Covariance::new(q64, s64).backward(weights);
        let h = 1e-6;
        for k in 0..4 {
            let (mut plus, mut minus) = (q64, q64);
            plus[k] += h;
            minus[k] -= h;
            let fd = (loss(plus, s64, weights) - loss(minus, s64, weights)) / (2.0 * h);
            assert!((fd - gq[k]).abs() < 1e-7, "quat {k}: fd {fd} analytic {}", gq[k]);
        }
        for k in 0..3 {
            let (mut plus, mut minus) = (s64, s64);
            plus[k] += h;
            minus[k] -= h;
            let fd = (loss(q64, plus, weights) - loss(q64, minus, weights)) / (2.0 * h);
            assert!((fd - gs[k]).abs() < 1e-7, "scale {k}: fd {fd} analytic {}", gs[k]);
        }
    }

    #[test]
    fn zero_quaternion_is_identity_with_zero_gradient() {
        let c = Covariance::new([0.0; 4], [1.0, 2.0, 3.0]);
        assert_eq!(c.sigma, DMat3::from_diagonal(DVec3::new(1.0, 4.0, 9.0)));
        let (gq, gs) = c.backward(DMat3::IDENTITY);
        assert_eq!(gq, [0.0; 4]);
        assert_eq!(gs, [2.0, 4.0, 6.0]);
    }
}
