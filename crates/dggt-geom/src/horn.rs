//! The rotation that best aligns paired, centred points (Horn's closed form): the unit quaternion maximising
//! `qᵀ N q`, `N` the 4 x 4 symmetric matrix built from the pairs' cross-covariance `S[a][b] = Σ w p_a q_b`, is
//! its top eigenvector, found here by cyclic Jacobi rotations (exact to rounding for a 4 x 4 matrix after a
//! handful of sweeps). Both the similarity that aligns predicted cameras to true ones and the rigid motion of a
//! moving object between two times are built on it.

use glam::DQuat;

/// The rotation `R` maximising `Σ w qᵢ · R pᵢ` for centred pairs whose cross-covariance is `s`
/// (`s[a][b] = Σ w pᵢ[a] qᵢ[b]`); `None` when it is not finite.
pub fn best_rotation(s: &[[f64; 3]; 3]) -> Option<DQuat> {
    let [[xx, xy, xz], [yx, yy, yz], [zx, zy, zz]] = *s;
    let n = [
        [xx + yy + zz, yz - zy, zx - xz, xy - yx],
        [yz - zy, xx - yy - zz, xy + yx, zx + xz],
        [zx - xz, xy + yx, -xx + yy - zz, yz + zy],
        [xy - yx, zx + xz, yz + zy, -xx - yy + zz],
    ];
    let (values, vectors) = symmetric_eigen4(n);
    let best = (0..4).max_by(|&a, &b| values[a].total_cmp(&values[b]))?;
    let [w, x, y, z] = std::array::from_fn(|row| vectors[row][best]);
    let quaternion = DQuat::from_xyzw(x, y, z, w);
    let length = quaternion.length();
    (length > 0.0 && length.is_finite()).then(|| quaternion / length)
}

/// Eigenvalues and eigenvectors (as columns) of a symmetric 4 x 4 matrix by cyclic Jacobi rotations.
fn symmetric_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = a.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    for _sweep in 0..64 {
        let off: f64 = (0..4).flat_map(|p| (p + 1..4).map(move |q| (p, q))).map(|(p, q)| a[p][q] * a[p][q]).sum();
        if off == 0.0 || off.sqrt() <= 1e-15 * scale {
            break;
        }
        for p in 0..4 {
            for q in p + 1..4 {
                if a[p][q] == 0.0 {
                    continue;
                }
                // The rotation in the (p, q) plane that zeroes a[p][q].
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = if theta == 0.0 { 1.0 } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in &mut a {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p], a[q]);
                for k in 0..4 {
                    a[p][k] = c * row_p[k] - s * row_q[k];
                    a[q][k] = s * row_p[k] + c * row_q[k];
                }
                for row in &mut v {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    (std::array::from_fn(|i| a[i][i]), v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn the_rotation_of_exact_pairs_is_recovered() {
        let truth = DQuat::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.3);
        let points = [DVec3::X, DVec3::Y * 2.0, DVec3::Z * 3.0, DVec3::new(-1.0, -2.0, -3.0)];
        let mut s = [[0.0; 3]; 3];
        for p in points {
            let q = truth * p;
            for a in 0..3 {
                for b in 0..3 {
                    s[a][b] += p[a] * q[b];
                }
            }
        }
        let found = best_rotation(&s).unwrap();
        assert!(found.dot(truth).abs() > 1.0 - 1e-12, "{found} vs {truth}");
        assert!(best_rotation(&[[f64::NAN; 3]; 3]).is_none());
    }
}
