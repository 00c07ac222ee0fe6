//! The backward pass of projection: every view's footprint gradients pulled back to each Gaussian's mean,
//! quaternion and scales.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::Grid;
use super::math::{
    M3, V3, apply, dot, mat_scaled, mat_sum, outer, product, scale_columns, scaled, sum3, transpose, v3,
};
use super::project::{Camera, Covariance, Ewa, camera, covariance, ewa};

/// `dL/du` for `R(u)` given `dL/dR` (rows), the quaternion `w x y z` treated as unconstrained.
#[cube]
pub fn rotation_backward(cov: Covariance, g: M3) -> (f32, f32, f32, f32) {
    let (w, x, y, z) = (cov.w, cov.x, cov.y, cov.z);
    let gw = 2.0 * (x * (g.r2.y - g.r1.z) + y * (g.r0.z - g.r2.x) + z * (g.r1.x - g.r0.y));
    let gx =
        2.0 * (y * (g.r0.y + g.r1.x) + z * (g.r0.z + g.r2.x) + w * (g.r2.y - g.r1.z)) - 4.0 * x * (g.r1.y + g.r2.z);
    let gy =
        2.0 * (x * (g.r0.y + g.r1.x) + z * (g.r1.z + g.r2.y) + w * (g.r0.z - g.r2.x)) - 4.0 * y * (g.r0.x + g.r2.z);
    let gz =
        2.0 * (x * (g.r0.z + g.r2.x) + y * (g.r1.z + g.r2.y) + w * (g.r1.x - g.r0.y)) - 4.0 * z * (g.r0.x + g.r1.y);
    (gw, gx, gy, gz)
}

/// The gradients of the camera-space covariance and of the projection Jacobian's two rows, from the conic's.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct FootprintBackward {
    pub g_cov_camera: M3,
    pub g_j0: V3,
    pub g_j1: V3,
}

/// Back through `conic = cov2d⁻¹` and `cov2d = J Σc Jᵀ`, given `dL/dconic = (ga, gb, gc)`.
#[cube]
pub fn conic_backward(e: Ewa, ga: f32, gb: f32, gc: f32) -> FootprintBackward {
    // conic = cov2d⁻¹ as a symmetric Q; dL/dcov2d = -Q (dL/dQ) Q with dL/dQ = [[ga, gb/2], [gb/2, gc]].
    let hb = 0.5 * gb;
    let (qa, qb, qc) = (e.a, e.b, e.c);
    let m00 = qa * ga + qb * hb;
    let m01 = qa * hb + qb * gc;
    let m10 = qb * ga + qc * hb;
    let m11 = qb * hb + qc * gc;
    let g00 = -(m00 * qa + m01 * qb);
    let g01 = -(m00 * qb + m01 * qc);
    let g10 = -(m10 * qa + m11 * qb);
    let g11 = -(m10 * qb + m11 * qc);
    let j0 = e.j0;
    let j1 = e.j1;
    let g_cov_camera = mat_sum(
        mat_sum(mat_scaled(outer(j0, j0), g00), mat_scaled(outer(j0, j1), g01)),
        mat_sum(mat_scaled(outer(j1, j0), g10), mat_scaled(outer(j1, j1), g11)),
    );
    // cov2d = J Σc Jᵀ with symmetric Σc: dL/dJ = 2 (dL/dcov2d) J Σc, row by row.
    let s0 = apply(e.cov_camera, j0);
    let s1 = apply(e.cov_camera, j1);
    let g_j0 = scaled(sum3(scaled(s0, g00), scaled(s1, g01)), 2.0);
    let g_j1 = scaled(sum3(scaled(s0, g10), scaled(s1, g11)), 2.0);
    FootprintBackward { g_cov_camera, g_j0, g_j1 }
}

/// `dL/dpoint` in camera space: through the projected mean (`gmx`, `gmy`), the depth (`gdepth`) and the
/// Jacobian's dependence on the point (guard-band clamping included).
#[cube]
pub fn point_backward(e: Ewa, cam: Camera, point: V3, g: FootprintBackward, gmx: f32, gmy: f32, gdepth: f32) -> V3 {
    let g_j0 = g.g_j0;
    let g_j1 = g.g_j1;
    let (x, y, z) = (point.x, point.y, point.z);
    let (fx, fy) = (cam.fx, cam.fy);
    let (tx, ty) = (e.tx, e.ty);
    let z2 = z * z;
    let z3 = z2 * z;
    let mut gpx = gmx * fx / z;
    let mut gpy = gmy * fy / z;
    let mut gpz = -(gmx * fx * x + gmy * fy * y) / z2 + gdepth;
    gpz += -g_j0.x * fx / z2 - g_j1.y * fy / z2 + 2.0 * (g_j0.z * fx * tx + g_j1.z * fy * ty) / z3;
    let glx = -g_j0.z * fx / z2;
    let gly = -g_j1.z * fy / z2;
    // Unclamped: tx = x. Clamped: tx = z * bound, so dtx/dx = 0 and dtx/dz = tx / z.
    if e.clamped_x {
        gpz += glx * tx / z;
    } else {
        gpx += glx;
    }
    if e.clamped_y {
        gpz += gly * ty / z;
    } else {
        gpy += gly;
    }
    v3(gpx, gpy, gpz)
}

/// Pulls the footprint gradients of every view (`footprint_grads`, laid out as in
/// [`composite_backward_kernel`]) back to the Gaussian's mean, quaternion and scales: one unit per Gaussian,
/// views in order. Writes `grad_means [N, 3]`, `grad_quats [N, 4]`, `grad_scales [N, 3]`.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn project_backward_kernel(
    means: &Tensor<f32>,
    quats: &Tensor<f32>,
    scales: &Tensor<f32>,
    viewmats: &Tensor<f32>,
    intrinsics: &Tensor<f32>,
    reasons: &Tensor<u32>,
    footprint_grads: &Tensor<f32>,
    grad_means: &mut Tensor<f32>,
    grad_quats: &mut Tensor<f32>,
    grad_scales: &mut Tensor<f32>,
    grid: Grid,
    eps2d: f32,
) {
    let n = ABSOLUTE_POS;
    let count = grid.count as usize;
    if n >= count {
        terminate!();
    }
    let mut gmx_sum = 0.0f32;
    let mut gmy_sum = 0.0f32;
    let mut gmz_sum = 0.0f32;
    let mut gsx_sum = 0.0f32;
    let mut gsy_sum = 0.0f32;
    let mut gsz_sum = 0.0f32;
    let mut g_qw = 0.0f32;
    let mut g_qx = 0.0f32;
    let mut g_qy = 0.0f32;
    let mut g_qz = 0.0f32;
    let mean = v3(means[3 * n], means[3 * n + 1], means[3 * n + 2]);
    let cov = covariance(quats, scales, n);
    let pairs = grid.views as usize * count;
    for v in 0..grid.views as usize {
        let k = v * count + n;
        if reasons[k] == 0 {
            let cam = camera(viewmats, intrinsics, v);
            let point = sum3(apply(cam.rotation, mean), cam.translation);
            let e = ewa(cov, cam, point, grid.width as f32, grid.height as f32, eps2d);
            let conic = 2 * pairs + 3 * k;
            let (ga, gb, gc) = (footprint_grads[conic], footprint_grads[conic + 1], footprint_grads[conic + 2]);
            let g = conic_backward(e, ga, gb, gc);
            let (gmx, gmy, gdepth) =
                (footprint_grads[2 * k], footprint_grads[2 * k + 1], footprint_grads[5 * pairs + k]);
            let g_point = point_backward(e, cam, point, g, gmx, gmy, gdepth);
            let (gpx, gpy, gpz) = (g_point.x, g_point.y, g_point.z);
            let g_cov_camera = g.g_cov_camera;
            let rt = transpose(cam.rotation);
            let g_mean = apply(rt, v3(gpx, gpy, gpz));
            gmx_sum += g_mean.x;
            gmy_sum += g_mean.y;
            gmz_sum += g_mean.z;
            let g_sigma = product(product(rt, g_cov_camera), cam.rotation);

            // Σ = M Mᵀ: dL/dM = (G + Gᵀ) M.
            let g_factor = product(mat_sum(g_sigma, transpose(g_sigma)), cov.factor);
            let gf_cols = transpose(g_factor);
            let r_cols = transpose(cov.rotation);
            gsx_sum += dot(gf_cols.r0, r_cols.r0);
            gsy_sum += dot(gf_cols.r1, r_cols.r1);
            gsz_sum += dot(gf_cols.r2, r_cols.r2);
            if !cov.sanitised {
                let g_rotation = scale_columns(g_factor, cov.scale);
                let (uw, ux, uy, uz) = rotation_backward(cov, g_rotation);
                // Jacobian of q / |q|: (I - u uᵀ) / |q|.
                let along = uw * cov.w + ux * cov.x + uy * cov.y + uz * cov.z;
                g_qw += (uw - cov.w * along) / cov.norm;
                g_qx += (ux - cov.x * along) / cov.norm;
                g_qy += (uy - cov.y * along) / cov.norm;
                g_qz += (uz - cov.z * along) / cov.norm;
            }
        }
    }
    grad_means[3 * n] = gmx_sum;
    grad_means[3 * n + 1] = gmy_sum;
    grad_means[3 * n + 2] = gmz_sum;
    grad_scales[3 * n] = gsx_sum;
    grad_scales[3 * n + 1] = gsy_sum;
    grad_scales[3 * n + 2] = gsz_sum;
    grad_quats[4 * n] = g_qw;
    grad_quats[4 * n + 1] = g_qx;
    grad_quats[4 * n + 2] = g_qy;
    grad_quats[4 * n + 3] = g_qz;
}
