//! Projection: each Gaussian's covariance factor, each view's camera, the EWA footprint in the image (the
//! Jacobian at the guard-band-limited point), and the kernel that projects and culls every (view, Gaussian)
//! pair. The forward quantities the backward pass also needs (`Covariance`, `Camera`, `Ewa`) live here.
//!
//! Culling codes: `0` kept, then [`CullReason`](crate::CullReason) in declaration order starting at `1`
//! (`NonFinite` .. `OutsideImage`); they index the statistics row directly (`1 + code`).

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::Grid;
use super::math::{M3, V3, apply, cross, dot, finite, product, rotation, scale_columns, sum3, transpose, v3};
use crate::constants::{ALPHA_THRESHOLD, GUARD_BAND_F32, MAX_BOX_SIGMAS_F32, QUAT_MIN_NORM_F32};

pub const CULL_NON_FINITE: u32 = 1;
pub const CULL_TRANSPARENT: u32 = 2;
pub const CULL_NEAR_PLANE: u32 = 3;
pub const CULL_FAR_PLANE: u32 = 4;
pub const CULL_DEGENERATE: u32 = 5;
pub const CULL_OUTSIDE_IMAGE: u32 = 6;

/// A Gaussian's covariance factor `M = R(q / |q|) diag(s)` and what its gradient needs.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct Covariance {
    pub w: f32,
    pub x: f32,
    pub y: f32,
    pub z: f32,
    pub norm: f32,
    pub sanitised: bool,
    pub rotation: M3,
    pub scale: V3,
    pub factor: M3,
}

#[cube]
pub fn covariance(quats: &Tensor<f32>, scales: &Tensor<f32>, n: usize) -> Covariance {
    let (qw, qx, qy, qz) = (quats[4 * n], quats[4 * n + 1], quats[4 * n + 2], quats[4 * n + 3]);
    let norm = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
    let sanitised = norm.is_nan() || norm < QUAT_MIN_NORM_F32;
    let mut w = 1.0f32;
    let mut x = 0.0f32;
    let mut y = 0.0f32;
    let mut z = 0.0f32;
    if !sanitised {
        w = qw / norm;
        x = qx / norm;
        y = qy / norm;
        z = qz / norm;
    }
    let rotation = rotation(w, x, y, z);
    let scale = v3(scales[3 * n], scales[3 * n + 1], scales[3 * n + 2]);
    let factor = scale_columns(rotation, scale);
    Covariance { w, x, y, z, norm, sanitised, rotation, scale, factor }
}

/// A pinhole camera: `p = R x + t`, focal lengths and principal point.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct Camera {
    pub rotation: M3,
    pub translation: V3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

#[cube]
pub fn camera(viewmats: &Tensor<f32>, intrinsics: &Tensor<f32>, v: usize) -> Camera {
    let m = 16 * v;
    let k = 9 * v;
    Camera {
        rotation: M3 {
            r0: v3(viewmats[m], viewmats[m + 1], viewmats[m + 2]),
            r1: v3(viewmats[m + 4], viewmats[m + 5], viewmats[m + 6]),
            r2: v3(viewmats[m + 8], viewmats[m + 9], viewmats[m + 10]),
        },
        translation: v3(viewmats[m + 3], viewmats[m + 7], viewmats[m + 11]),
        fx: intrinsics[k],
        fy: intrinsics[k + 4],
        cx: intrinsics[k + 2],
        cy: intrinsics[k + 5],
    }
}

/// The EWA projection of one Gaussian into one view, with the intermediates of its gradient.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct Ewa {
    pub tx: f32,
    pub ty: f32,
    pub clamped_x: bool,
    pub clamped_y: bool,
    pub j0: V3,
    pub j1: V3,
    /// `R Σ Rᵀ`.
    pub cov_camera: M3,
    /// 2D covariance `[[p, q], [q, r]]` including `eps2d`.
    pub p: f32,
    pub q: f32,
    pub r: f32,
    pub det: f32,
    /// Inverse 2D covariance `(a, b, c)`.
    pub a: f32,
    pub b: f32,
    pub c: f32,
    pub mx: f32,
    pub my: f32,
}

/// Guard-band limited `x / z` (times `z`) and whether the limit was active.
#[cube]
pub fn limited(coordinate: f32, z: f32, focal: f32, centre: f32, extent: f32) -> (f32, bool) {
    let tangent = 0.5 * extent / focal;
    let low = -(centre / focal + GUARD_BAND_F32 * tangent);
    let high = (extent - centre) / focal + GUARD_BAND_F32 * tangent;
    let ratio = coordinate / z;
    (z * ratio.max(low).min(high), ratio < low || ratio > high)
}

#[cube]
pub fn ewa(cov: Covariance, cam: Camera, point: V3, width: f32, height: f32, eps: f32) -> Ewa {
    let z = point.z;
    let (tx, clamped_x) = limited(point.x, z, cam.fx, cam.cx, width);
    let (ty, clamped_y) = limited(point.y, z, cam.fy, cam.cy, height);
    let j0 = v3(cam.fx / z, 0.0, -cam.fx * tx / (z * z));
    let j1 = v3(0.0, cam.fy / z, -cam.fy * ty / (z * z));
    let sigma = product(cov.factor, transpose(cov.factor));
    let cov_camera = product(product(cam.rotation, sigma), transpose(cam.rotation));
    // J Σc Jᵀ = A Aᵀ with rows a0, a1 of A = J R M; det = |a0 x a1|² (Lagrange's identity) stays accurate for
    // needle-like Gaussians.
    let to_image = transpose(product(cam.rotation, cov.factor));
    let a0 = apply(to_image, j0);
    let a1 = apply(to_image, j1);
    let p0 = dot(a0, a0);
    let q = dot(a0, a1);
    let r0 = dot(a1, a1);
    let p = p0 + eps;
    let r = r0 + eps;
    let normal = cross(a0, a1);
    let det = dot(normal, normal) + eps * (p0 + r0) + eps * eps;
    Ewa {
        tx,
        ty,
        clamped_x,
        clamped_y,
        j0,
        j1,
        cov_camera,
        p,
        q,
        r,
        det,
        a: r / det,
        b: -q / det,
        c: p / det,
        mx: cam.fx * point.x / z + cam.cx,
        my: cam.fy * point.y / z + cam.cy,
    }
}

/// Projects and culls every (view, Gaussian) pair: one unit per `k = v * N + n`.
///
/// Writes `means2d [V, N, 2]`, `conics [V, N, 3]`, `depths [V, N]`, `radii [V, N, 2]` (`u32`, zeros when
/// culled) and `reasons [V, N]` (`u32` culling codes).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn project_kernel(
    means: &Tensor<f32>,
    quats: &Tensor<f32>,
    scales: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    viewmats: &Tensor<f32>,
    intrinsics: &Tensor<f32>,
    means2d: &mut Tensor<f32>,
    conics: &mut Tensor<f32>,
    depths: &mut Tensor<f32>,
    radii: &mut Tensor<u32>,
    reasons: &mut Tensor<u32>,
    grid: Grid,
    near: f32,
    far: f32,
    eps2d: f32,
    #[comptime] channels: usize,
) {
    let k = ABSOLUTE_POS;
    let count = grid.count as usize;
    if k >= count * (grid.views as usize) {
        terminate!();
    }
    let v = k / count;
    let n = k % count;
    let mut opacity = opacities[n];
    if grid.per_view == 1 {
        opacity = opacities[k];
    }
    let mut all_finite = finite(opacity);
    for j in 0..3usize {
        all_finite = all_finite && finite(means[3 * n + j]) && finite(scales[3 * n + j]);
    }
    for j in 0..4usize {
        all_finite = all_finite && finite(quats[4 * n + j]);
    }
    for j in 0..channels {
        all_finite = all_finite && finite(colors[channels * n + j]);
    }

    let mut reason = 0u32;
    let mut mean2d_x = 0.0f32;
    let mut mean2d_y = 0.0f32;
    let mut conic_a = 0.0f32;
    let mut conic_b = 0.0f32;
    let mut conic_c = 0.0f32;
    let mut depth = 0.0f32;
    let mut radius_x = 0u32;
    let mut radius_y = 0u32;
    if !all_finite {
        reason = CULL_NON_FINITE;
    } else if opacity < ALPHA_THRESHOLD {
        reason = CULL_TRANSPARENT;
    } else {
        let cam = camera(viewmats, intrinsics, v);
        let mean = v3(means[3 * n], means[3 * n + 1], means[3 * n + 2]);
        let point = sum3(apply(cam.rotation, mean), cam.translation);
        if point.z.is_nan() || point.z <= near {
            reason = CULL_NEAR_PLANE;
        } else if point.z >= far {
            reason = CULL_FAR_PLANE;
        } else {
            let cov = covariance(quats, scales, n);
            let (w, h) = (grid.width as f32, grid.height as f32);
            let e = ewa(cov, cam, point, w, h, eps2d);
            let valid = e.det > 0.0
                && finite(e.det)
                && finite(e.p)
                && finite(e.q)
                && finite(e.r)
                && finite(e.a)
                && finite(e.b)
                && finite(e.c)
                && finite(e.mx)
                && finite(e.my);
            if !valid {
                reason = CULL_DEGENERATE;
            } else {
                let extent = (2.0 * (opacity / ALPHA_THRESHOLD).ln()).max(0.0).sqrt().min(MAX_BOX_SIGMAS_F32);
                let rx = (extent * e.p.sqrt()).ceil();
                let ry = (extent * e.r.sqrt()).ceil();
                if rx <= 0.0 && ry <= 0.0 {
                    reason = CULL_TRANSPARENT;
                } else if e.mx + rx <= 0.0 || e.mx - rx >= w || e.my + ry <= 0.0 || e.my - ry >= h {
                    reason = CULL_OUTSIDE_IMAGE;
                } else {
                    mean2d_x = e.mx;
                    mean2d_y = e.my;
                    conic_a = e.a;
                    conic_b = e.b;
                    conic_c = e.c;
                    depth = point.z;
                    radius_x = rx as u32;
                    radius_y = ry as u32;
                }
            }
        }
    }
    means2d[2 * k] = mean2d_x;
    means2d[2 * k + 1] = mean2d_y;
    conics[3 * k] = conic_a;
    conics[3 * k + 1] = conic_b;
    conics[3 * k + 2] = conic_c;
    depths[k] = depth;
    radii[2 * k] = radius_x;
    radii[2 * k + 1] = radius_y;
    reasons[k] = reason;
}
