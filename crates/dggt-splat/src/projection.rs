//! EWA splatting: each 3D Gaussian becomes a 2D Gaussian footprint in each view (mean, conic, depth, bounding
//! radius), or is culled with a [`CullReason`]; and the vector-Jacobian product of that map.
//!
//! gsplat's "classic" pinhole projection: `p = R x + t`; the perspective Jacobian is evaluated at the camera
//! point with `x/z` and `y/z` clamped to 1.3x the field of view (so Gaussians far outside the image do not blow
//! up), while the projected mean uses the unclamped point; `eps2d` is added to the 2D covariance diagonal. The
//! bounding radius is opacity-aware, `ceil(min(3.33, sqrt(2 ln(255 o))) sigma)` per axis: outside it a pixel's
//! alpha is below 1/255 and would be skipped anyway, so the choice of box never changes a rendered value.
//!
//! Per-Gaussian math runs in `f64` on the `f32` inputs; the footprint is stored in `f32` for compositing.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::blocks::Reach;
use crate::constants::{ALPHA_THRESHOLD, GUARD_BAND, MAX_BOX_SIGMAS};
use crate::covariance::Covariance;
use crate::cull::CullReason;
use crate::gaussians::Gaussians;
use crate::settings::RasterSettings;
use crate::view::{PinholeView, ViewBatch};

/// The projected footprints of all Gaussians in all views. Dense (not packed): entry `[v, n]` exists for every
/// view and Gaussian; culled entries hold zeros and their reason.
///
/// | buffer | shape | meaning |
/// |---|---|---|
/// | `means2d` | `[V, N, 2]` | projected centre in pixels (from the unclamped camera point) |
/// | `depths` | `[V, N]` | camera-space `z` |
/// | `conics` | `[V, N, 3]` | inverse 2D covariance `(a, b, c)` = `[[a, b], [b, c]]` |
/// | `radii` | `[V, N, 2]` | bounding-box half-size in whole pixels; `0` = culled |
/// | `culled` | `[V, N]` | `None` if kept, else why not |
///
/// Beside them, for compositing: how far each kept footprint reaches (its falloff cutoff and the box of pixels
/// above the alpha threshold), worked out once per view and Gaussian for the forward and the backward pass alike.
#[derive(Debug, Clone, PartialEq)]
pub struct Projection {
    pub means2d: Vec<f32>,
    pub depths: Vec<f32>,
    pub conics: Vec<f32>,
    pub radii: Vec<u32>,
    pub culled: Vec<Option<CullReason>>,
    /// `[V, N]`; [`Reach::NOWHERE`] where culled.
    pub(crate) reaches: Vec<Reach>,
}

/// The 2D footprint of a kept Gaussian, as compositing reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Footprint {
    pub mean2d: [f32; 2],
    pub conic: [f32; 3],
    pub depth: f32,
    pub radius: [u32; 2],
}

/// `dL/d` of one footprint's differentiable parts.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct FootprintGrad {
    pub mean2d: [f64; 2],
    pub conic: [f64; 3],
    pub depth: f64,
}

/// `dL/d` of one Gaussian's geometry (view-independent inputs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct GeometryGrad {
    pub mean: [f64; 3],
    pub quat: [f64; 4],
    pub scale: [f64; 3],
}

impl Projection {
    /// Projects every Gaussian into every view (in parallel; the result does not depend on the thread count).
    pub(crate) fn compute(gaussians: &Gaussians, views: &ViewBatch, settings: &RasterSettings) -> Self {
        let count = gaussians.len();
        let total = views.len() * count;
        let mut projection = Projection {
            means2d: vec![0.0; 2 * total],
            depths: vec![0.0; total],
            conics: vec![0.0; 3 * total],
            radii: vec![0; 2 * total],
            culled: vec![None; total],
            reaches: vec![Reach::NOWHERE; total],
        };
        let Projection { means2d, depths, conics, radii, culled, reaches } = &mut projection;
        let entries = means2d
            .par_chunks_mut(2)
            .zip(conics.par_chunks_mut(3))
            .zip(radii.par_chunks_mut(2))
            .zip(depths.par_iter_mut())
            .zip(culled.par_iter_mut())
            .zip(reaches.par_iter_mut());
        entries.enumerate().for_each(|(k, (((((mean2d, conic), radius), depth), culled), reach))| {
            let (v, i) = (k / count, k % count);
            match project(gaussians, i, v, &views.views()[v], views, settings) {
                Ok(footprint) => {
                    mean2d.copy_from_slice(&footprint.mean2d);
                    conic.copy_from_slice(&footprint.conic);
                    radius.copy_from_slice(&footprint.radius);
                    *depth = footprint.depth;
                    *reach = Reach::new(footprint.conic, gaussians.opacity(v, i), ALPHA_THRESHOLD);
                }
                Err(reason) => *culled = Some(reason),
            }
        });
        projection
    }

    /// The footprint at flat index `k = v * N + n`, or `None` if culled.
    pub(crate) fn footprint(&self, k: usize) -> Option<Footprint> {
        if self.culled[k].is_some() {
            return None;
        }
        Some(Footprint {
            mean2d: [self.means2d[2 * k], self.means2d[2 * k + 1]],
            conic: [self.conics[3 * k], self.conics[3 * k + 1], self.conics[3 * k + 2]],
            depth: self.depths[k],
            radius: [self.radii[2 * k], self.radii[2 * k + 1]],
        })
    }
}

/// Projects Gaussian `i` into view `v`, or says why it is culled (first failing rule, in [`CullReason`] order).
fn project(
    gaussians: &Gaussians,
    i: usize,
    v: usize,
    view: &PinholeView,
    views: &ViewBatch,
    settings: &RasterSettings,
) -> Result<Footprint, CullReason> {
    let opacity = gaussians.opacity(v, i);
    if !gaussians.is_finite(i) || !opacity.is_finite() {
        return Err(CullReason::NonFinite);
    }
    if opacity < ALPHA_THRESHOLD {
        return Err(CullReason::Transparent);
    }
    let point = camera_point(view, gaussians.mean(i));
    if point.z.is_nan() || point.z <= settings.near_plane as f64 {
        return Err(CullReason::NearPlane);
    }
    if point.z >= settings.far_plane as f64 {
        return Err(CullReason::FarPlane);
    }
    let ewa = Ewa::new(gaussians, i, view, point, views, settings.eps2d);
    if !ewa.is_valid() {
        return Err(CullReason::Degenerate);
    }
    let extent = MAX_BOX_SIGMAS.min((2.0 * (opacity as f64 / ALPHA_THRESHOLD as f64).ln()).max(0.0).sqrt());
    let radius = [(extent * ewa.cov2d[0].sqrt()).ceil(), (extent * ewa.cov2d[2].sqrt()).ceil()];
    if radius[0] <= 0.0 && radius[1] <= 0.0 {
        return Err(CullReason::Transparent);
    }
    let [mx, my] = ewa.mean2d;
    let (width, height) = (views.width() as f64, views.height() as f64);
    if mx + radius[0] <= 0.0 || mx - radius[0] >= width || my + radius[1] <= 0.0 || my - radius[1] >= height {
        return Err(CullReason::OutsideImage);
    }
    let footprint = Footprint {
        mean2d: ewa.mean2d.map(|x| x as f32),
        conic: ewa.conic.map(|x| x as f32),
        depth: point.z as f32,
        radius: radius.map(|r| r as u32),
    };
    let representable =
        footprint.mean2d.iter().chain(&footprint.conic).all(|x| x.is_finite()) && footprint.depth.is_finite();
    if !representable {
        return Err(CullReason::Degenerate);
    }
    Ok(footprint)
}

/// `dL/d(mean, quat, scale)` of Gaussian `i` from `dL/d(footprint in view v)`. Only valid for a Gaussian the
/// forward pass kept in that view.
pub(crate) fn project_backward(
    gaussians: &Gaussians,
    i: usize,
    view: &PinholeView,
    views: &ViewBatch,
    settings: &RasterSettings,
    grad: &FootprintGrad,
) -> GeometryGrad {
    let point = camera_point(view, gaussians.mean(i));
    Ewa::new(gaussians, i, view, point, views, settings.eps2d).backward(grad)
}

fn camera_point(view: &PinholeView, mean: [f32; 3]) -> DVec3 {
    rows_to_matrix(view.rotation()) * DVec3::from_array(mean.map(f64::from)) + DVec3::from_array(view.translation())
}

fn rows_to_matrix(rows: [[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(&rows).transpose()
}

/// `a bᵀ`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The projection of one Gaussian into one view with every intermediate the gradient needs.
struct Ewa {
    covariance: Covariance,
    /// World-to-camera rotation `R`.
    rotation: DMat3,
    /// Camera-space centre.
    point: DVec3,
    focal: [f64; 2],
    /// Camera-space `x` and `y` after the guard-band clamp (`z * clamp(x / z)`).
    limited: [f64; 2],
    clamped: [bool; 2],
    /// Rows of the 2x3 perspective Jacobian.
    jacobian: [DVec3; 2],
    /// Camera-space covariance `R Σ Rᵀ`.
    cov_camera: DMat3,
    /// 2D covariance `(p, q, r)` = `[[p, q], [q, r]]`, including `eps2d`.
    cov2d: [f64; 3],
    det: f64,
    conic: [f64; 3],
    mean2d: [f64; 2],
}

impl Ewa {
    fn new(gaussians: &Gaussians, i: usize, view: &PinholeView, point: DVec3, views: &ViewBatch, eps2d: f32) -> Self {
        let covariance = Covariance::new(gaussians.quat(i).map(f64::from), gaussians.scale(i).map(f64::from));
        let rotation = rows_to_matrix(view.rotation());
        let (fx, fy, cx, cy) = (view.fx as f64, view.fy as f64, view.cx as f64, view.cy as f64);
        let (width, height) = (views.width() as f64, views.height() as f64);
        let z = point.z;
        let limit = |coordinate: f64, focal: f64, centre: f64, extent: f64| {
            let tangent = 0.5 * extent / focal;
            let low = -(centre / focal + GUARD_BAND * tangent);
            let high = (extent - centre) / focal + GUARD_BAND * tangent;
            let ratio = coordinate / z;
            // max/min rather than clamp: with extreme intrinsics rounding may order the bounds wrongly.
            (z * ratio.max(low).min(high), ratio < low || ratio > high)
        };
        let (tx, clamped_x) = limit(point.x, fx, cx, width);
        let (ty, clamped_y) = limit(point.y, fy, cy, height);
        let jacobian = [DVec3::new(fx / z, 0.0, -fx * tx / (z * z)), DVec3::new(0.0, fy / z, -fy * ty / (z * z))];
        let cov_camera = rotation * covariance.sigma * rotation.transpose();
        // J Σc Jᵀ = A Aᵀ with A = J R M (2x3, rows a0 a1). Its determinant is |a0 x a1|² (Lagrange's identity),
        // which stays accurate for needle-like Gaussians where p r - q² cancels catastrophically.
        let to_image = (rotation * covariance.factor).transpose();
        let (a0, a1) = (to_image * jacobian[0], to_image * jacobian[1]);
        let eps = eps2d as f64;
        let (p0, q, r0) = (a0.length_squared(), a0.dot(a1), a1.length_squared());
        let (p, r) = (p0 + eps, r0 + eps);
        let det = a0.cross(a1).length_squared() + eps * (p0 + r0) + eps * eps;
        Self {
            covariance,
            rotation,
            point,
            focal: [fx, fy],
            limited: [tx, ty],
            clamped: [clamped_x, clamped_y],
            jacobian,
            cov_camera,
            cov2d: [p, q, r],
            det,
            conic: [r / det, -q / det, p / det],
            mean2d: [fx * point.x / z + cx, fy * point.y / z + cy],
        }
    }

    /// A positive-definite, finite 2D covariance with a finite inverse and mean. (With `eps2d > 0` the
    /// determinant is positive by construction; overflow and `eps2d = 0` remain.)
    fn is_valid(&self) -> bool {
        self.det > 0.0
            && self.det.is_finite()
            && self.cov2d.iter().chain(&self.conic).chain(&self.mean2d).all(|x| x.is_finite())
    }

    fn backward(&self, grad: &FootprintGrad) -> GeometryGrad {
        let [a, b, c] = self.conic;
        let [ga, gb, gc] = grad.conic;
        // conic = cov2d⁻¹ as a symmetric matrix Q; dL/dcov2d = -Q (dL/dQ) Q, with dL/dQ = [[ga, gb/2], [gb/2, gc]]
        // because b appears twice in Q.
        let q = [[a, b], [b, c]];
        let gq = [[ga, 0.5 * gb], [0.5 * gb, gc]];
        let qg = mul2(q, gq);
        let qgq = mul2(qg, q);
        let g_cov2d = [[-qgq[0][0], -qgq[0][1]], [-qgq[1][0], -qgq[1][1]]];

        let [j0, j1] = self.jacobian;
        let g_cov_camera = outer(j0, j0) * g_cov2d[0][0]
            + outer(j0, j1) * g_cov2d[0][1]
            + outer(j1, j0) * g_cov2d[1][0]
            + outer(j1, j1) * g_cov2d[1][1];
        // cov2d = J Σc Jᵀ with symmetric Σc and dL/dcov2d: dL/dJ = 2 (dL/dcov2d) J Σc, row by row.
        let (s0, s1) = (self.cov_camera * j0, self.cov_camera * j1);
        let g_j0 = 2.0 * (s0 * g_cov2d[0][0] + s1 * g_cov2d[0][1]);
        let g_j1 = 2.0 * (s0 * g_cov2d[1][0] + s1 * g_cov2d[1][1]);

        let DVec3 { x, y, z } = self.point;
        let [fx, fy] = self.focal;
        let [tx, ty] = self.limited;
        let (z2, z3) = (z * z, z * z * z);
        let [gmx, gmy] = grad.mean2d;
        let mut g_point = DVec3::new(gmx * fx / z, gmy * fy / z, -(gmx * fx * x + gmy * fy * y) / z2 + grad.depth);
        // J00 = fx/z, J11 = fy/z, J02 = -fx tx/z², J12 = -fy ty/z².
        g_point.z += -g_j0.x * fx / z2 - g_j1.y * fy / z2 + 2.0 * (g_j0.z * fx * tx + g_j1.z * fy * ty) / z3;
        let g_limited = [-g_j0.z * fx / z2, -g_j1.z * fy / z2];
        // Unclamped: tx = x. Clamped: tx = z * bound, so dtx/dx = 0 and dtx/dz = tx / z.
        if self.clamped[0] {
            g_point.z += g_limited[0] * tx / z;
        } else {
            g_point.x += g_limited[0];
        }
        if self.clamped[1] {
            g_point.z += g_limited[1] * ty / z;
        } else {
            g_point.y += g_limited[1];
        }

        let mean = self.rotation.transpose() * g_point;
        let g_sigma = self.rotation.transpose() * g_cov_camera * self.rotation;
        let (quat, scale) = self.covariance.backward(g_sigma);
        GeometryGrad { mean: mean.to_array(), quat, scale }
    }
}

fn mul2(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaussians::Opacities;
    use dggt_geom::ImageSize;

    fn view() -> (ViewBatch, PinholeView) {
        let c = 0.3f32.cos();
        let s = 0.3f32.sin();
        let view = PinholeView {
            world_to_camera: [[c, 0.0, s, 0.2], [0.0, 1.0, 0.0, -0.1], [-s, 0.0, c, 0.5]],
            fx: 40.0,
            fy: 38.0,
            cx: 16.0,
            cy: 12.5,
        };
        (ViewBatch::new(vec![view], ImageSize::new(32, 24).unwrap()).unwrap(), view)
    }

    /// Weighted sum of the footprint, for finite differences of the whole projection.
    fn loss(ewa: &Ewa, weights: &FootprintGrad) -> f64 {
        ewa.mean2d.iter().zip(&weights.mean2d).map(|(a, b)| a * b).sum::<f64>()
            + ewa.conic.iter().zip(&weights.conic).map(|(a, b)| a * b).sum::<f64>()
            + ewa.point.z * weights.depth
    }

    fn check_against_finite_differences(mean: [f32; 3]) {
        let (views, view) = view();
        let quat = [0.9f32, 0.2, -0.4, 0.3];
        let scale = [0.4f32, 0.1, 0.25];
        let opacity = [0.7f32];
        let weights = FootprintGrad { mean2d: [0.3, -0.7], conic: [2.0, -1.5, 0.8], depth: 0.4 };
        let settings = RasterSettings::default();
        let eval = |mean: [f32; 3], quat: [f32; 4], scale: [f32; 3]| {
            let g = Gaussians::new(&mean, &quat, &scale, Opacities::Shared(&opacity), &[1.0], 1).unwrap();
            let point = camera_point(&view, mean);
            let ewa = Ewa::new(&g, 0, &view, point, &views, settings.eps2d);
            (loss(&ewa, &weights), ewa.clamped)
        };
        let g = Gaussians::new(&mean, &quat, &scale, Opacities::Shared(&opacity), &[1.0], 1).unwrap();
        let analytic = project_backward(&g, 0, &view, &views, &settings, &weights);
        // f32 inputs: steps large enough to dominate their rounding, relative tolerance accordingly.
        let h = 1e-3f32;
        let fd = |plus: f64, minus: f64| (plus - minus) / (2.0 * h as f64);
        let close = |fd: f64, a: f64, what: &str| {
            assert!((fd - a).abs() <= 2e-3 * (1.0 + a.abs()), "{what}: finite difference {fd}, analytic {a}");
        };
        for k in 0..3 {
            let (mut p, mut m) = (mean, mean);
            p[k] += h;
            m[k] -= h;
            close(fd(eval(p, quat, scale).0, eval(m, quat, scale).0), analytic.mean[k], &format!("mean {k}"));
            let (mut p, mut m) = (scale, scale);
            p[k] += h;
            m[k] -= h;
            close(fd(eval(mean, quat, p).0, eval(mean, quat, m).0), analytic.scale[k], &format!("scale {k}"));
        }
        for k in 0..4 {
            let (mut p, mut m) = (quat, quat);
            p[k] += h;
            m[k] -= h;
            close(fd(eval(mean, p, scale).0, eval(mean, m, scale).0), analytic.quat[k], &format!("quat {k}"));
        }
    }

    #[test]
    fn gradient_matches_finite_differences_inside_the_field_of_view() {
        check_against_finite_differences([0.1, -0.2, 2.5]);
    }

    #[test]
    fn gradient_matches_finite_differences_with_the_guard_band_clamp() {
        // x/z far beyond the image's right edge plus the guard band, y inside.
        let (views, view) = view();
        let mean = [4.0f32, 0.1, 2.0];
        let opacity = [0.7f32];
        let g =
            Gaussians::new(&mean, &[1.0, 0.0, 0.0, 0.0], &[0.3; 3], Opacities::Shared(&opacity), &[1.0], 1).unwrap();
        let ewa = Ewa::new(&g, 0, &view, camera_point(&view, mean), &views, 0.3);
        assert_eq!(ewa.clamped, [true, false]);
        check_against_finite_differences(mean);
    }
}
