//! The CubeCL kernels of the rasteriser, one per pipeline stage, in `f32`.
//!
//! Every kernel reads and writes flat, contiguous buffers with the layouts of the host pipeline (see
//! `Projection`, `TileBins` and `Images`): index `k = v * N + n` for per-(view, Gaussian) values, pixel
//! `p = (v * H + y) * W + x` for per-pixel values. Sizes arrive as runtime `u32` scalars; only the number of
//! colour channels is a compile-time constant (one compiled kernel per `K`), so that per-pixel colour
//! accumulators live in registers.
//!
//! Culling codes: `0` kept, then [`CullReason`](crate::CullReason) in declaration order starting at `1`
//! (`NonFinite` .. `OutsideImage`); they index the statistics row directly (`1 + code`).

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// `1 / 255`: footprints below this alpha are skipped; Gaussians below this opacity are culled.
const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
const MAX_ALPHA: f32 = 0.999;
const MIN_TRANSMITTANCE: f32 = 1e-4;
const MIN_DEPTH_ALPHA: f32 = 1e-10;
const GUARD_BAND: f32 = 0.3;
const MAX_BOX_SIGMAS: f32 = 3.33;
const QUAT_MIN_NORM: f32 = 1e-12;

pub const CULL_NON_FINITE: u32 = 1;
pub const CULL_TRANSPARENT: u32 = 2;
pub const CULL_NEAR_PLANE: u32 = 3;
pub const CULL_FAR_PLANE: u32 = 4;
pub const CULL_DEGENERATE: u32 = 5;
pub const CULL_OUTSIDE_IMAGE: u32 = 6;

/// Threads per cube of the one-cube prefix sum.
pub const SCAN_THREADS: u32 = 256;
/// [`SCAN_THREADS`] as the length of the shared segment sums.
const SCAN_LEN: usize = SCAN_THREADS as usize;

/// Float addition into a gradient buffer shared by many threads: a native `f32` atomic add where the device
/// has one, otherwise a compare-and-swap loop on the bits (`Atomic<u32>`). Both buffers hold `f32` bits.
#[cube]
pub trait FloatAdd: Send + Sync + 'static {
    type Slot: CubePrimitive;

    /// `buffer[index] += value`.
    fn add(buffer: &Tensor<Atomic<Self::Slot>>, index: usize, value: f32);
}

/// Native `f32` atomic add.
pub struct NativeAdd;

/// Compare-and-swap on the `u32` bits of an `f32`.
pub struct SwapAdd;

#[cube]
impl FloatAdd for NativeAdd {
    type Slot = f32;

    fn add(buffer: &Tensor<Atomic<f32>>, index: usize, value: f32) {
        if value != 0.0 {
            buffer[index].fetch_add(value);
        }
    }
}

#[cube]
impl FloatAdd for SwapAdd {
    type Slot = u32;

    fn add(buffer: &Tensor<Atomic<u32>>, index: usize, value: f32) {
        if value != 0.0 {
            let mut current = buffer[index].load();
            loop {
                let expected = current;
                let sum = f32::from_bits(expected) + value;
                current = buffer[index].compare_exchange_weak(expected, sum.to_bits());
                if current == expected {
                    break;
                }
            }
        }
    }
}

/// A 3-vector.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct V3 {
    x: f32,
    y: f32,
    z: f32,
}

/// A 3x3 matrix as rows.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct M3 {
    r0: V3,
    r1: V3,
    r2: V3,
}

#[cube]
fn v3(x: f32, y: f32, z: f32) -> V3 {
    V3 { x, y, z }
}

#[cube]
fn dot(a: V3, b: V3) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

#[cube]
fn scaled(a: V3, s: f32) -> V3 {
    v3(a.x * s, a.y * s, a.z * s)
}

#[cube]
fn sum3(a: V3, b: V3) -> V3 {
    v3(a.x + b.x, a.y + b.y, a.z + b.z)
}

#[cube]
fn cross(a: V3, b: V3) -> V3 {
    v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)
}

#[cube]
fn transpose(m: M3) -> M3 {
    M3 { r0: v3(m.r0.x, m.r1.x, m.r2.x), r1: v3(m.r0.y, m.r1.y, m.r2.y), r2: v3(m.r0.z, m.r1.z, m.r2.z) }
}

/// `m v`.
#[cube]
fn apply(m: M3, v: V3) -> V3 {
    v3(dot(m.r0, v), dot(m.r1, v), dot(m.r2, v))
}

/// `a b`.
#[cube]
fn product(a: M3, b: M3) -> M3 {
    let bt = transpose(b);
    M3 { r0: apply(bt, a.r0), r1: apply(bt, a.r1), r2: apply(bt, a.r2) }
}

/// `a bᵀ`.
#[cube]
fn outer(a: V3, b: V3) -> M3 {
    M3 { r0: scaled(b, a.x), r1: scaled(b, a.y), r2: scaled(b, a.z) }
}

#[cube]
fn mat_sum(a: M3, b: M3) -> M3 {
    M3 { r0: sum3(a.r0, b.r0), r1: sum3(a.r1, b.r1), r2: sum3(a.r2, b.r2) }
}

#[cube]
fn mat_scaled(a: M3, s: f32) -> M3 {
    M3 { r0: scaled(a.r0, s), r1: scaled(a.r1, s), r2: scaled(a.r2, s) }
}

/// `m diag(s)`.
#[cube]
fn scale_columns(m: M3, s: V3) -> M3 {
    M3 {
        r0: v3(m.r0.x * s.x, m.r0.y * s.y, m.r0.z * s.z),
        r1: v3(m.r1.x * s.x, m.r1.y * s.y, m.r1.z * s.z),
        r2: v3(m.r2.x * s.x, m.r2.y * s.y, m.r2.z * s.z),
    }
}

#[cube]
fn finite(x: f32) -> bool {
    !(x.is_nan() || x.is_inf())
}

/// Rotation matrix of the unit quaternion `w x y z`.
#[cube]
fn rotation(w: f32, x: f32, y: f32, z: f32) -> M3 {
    M3 {
        r0: v3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
        r1: v3(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
        r2: v3(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)),
    }
}

/// A Gaussian's covariance factor `M = R(q / |q|) diag(s)` and what its gradient needs.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct Covariance {
    w: f32,
    x: f32,
    y: f32,
    z: f32,
    norm: f32,
    sanitised: bool,
    rotation: M3,
    scale: V3,
    factor: M3,
}

#[cube]
fn covariance(quats: &Tensor<f32>, scales: &Tensor<f32>, n: usize) -> Covariance {
    let (qw, qx, qy, qz) = (quats[4 * n], quats[4 * n + 1], quats[4 * n + 2], quats[4 * n + 3]);
    let norm = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
    let sanitised = norm.is_nan() || norm < QUAT_MIN_NORM;
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
    rotation: M3,
    translation: V3,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
}

#[cube]
fn camera(viewmats: &Tensor<f32>, intrinsics: &Tensor<f32>, v: usize) -> Camera {
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
    tx: f32,
    ty: f32,
    clamped_x: bool,
    clamped_y: bool,
    j0: V3,
    j1: V3,
    /// `R Σ Rᵀ`.
    cov_camera: M3,
    /// 2D covariance `[[p, q], [q, r]]` including `eps2d`.
    p: f32,
    q: f32,
    r: f32,
    det: f32,
    /// Inverse 2D covariance `(a, b, c)`.
    a: f32,
    b: f32,
    c: f32,
    mx: f32,
    my: f32,
}

/// Guard-band limited `x / z` (times `z`) and whether the limit was active.
#[cube]
fn limited(coordinate: f32, z: f32, focal: f32, centre: f32, extent: f32) -> (f32, bool) {
    let tangent = 0.5 * extent / focal;
    let low = -(centre / focal + GUARD_BAND * tangent);
    let high = (extent - centre) / focal + GUARD_BAND * tangent;
    let ratio = coordinate / z;
    (z * ratio.max(low).min(high), ratio < low || ratio > high)
}

#[cube]
fn ewa(cov: Covariance, cam: Camera, point: V3, width: f32, height: f32, eps: f32) -> Ewa {
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
    count: u32,
    views: u32,
    per_view: u32,
    width: u32,
    height: u32,
    near: f32,
    far: f32,
    eps2d: f32,
    #[comptime] channels: usize,
) {
    let k = ABSOLUTE_POS;
    let count = count as usize;
    if k >= count * (views as usize) {
        terminate!();
    }
    let v = k / count;
    let n = k % count;
    let mut opacity = opacities[n];
    if per_view == 1 {
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
            let (w, h) = (width as f32, height as f32);
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
                let extent = (2.0 * (opacity / ALPHA_THRESHOLD).ln()).max(0.0).sqrt().min(MAX_BOX_SIGMAS);
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

/// Tiles `[x0, x1) x [y0, y1)` touched by the box `mean2d ± radius`, clipped to the grid.
#[cube]
fn tile_rect(mx: f32, my: f32, rx: u32, ry: u32, tile_size: u32, tiles_x: u32, tiles_y: u32) -> (u32, u32, u32, u32) {
    let size = tile_size as f32;
    let (rxf, ryf) = (rx as f32, ry as f32);
    let (tilesx, tilesy) = (tiles_x as f32, tiles_y as f32);
    let x0 = ((mx - rxf) / size).floor().max(0.0).min(tilesx);
    let x1 = ((mx + rxf) / size).ceil().max(0.0).min(tilesx);
    let y0 = ((my - ryf) / size).floor().max(0.0).min(tilesy);
    let y1 = ((my + ryf) / size).ceil().max(0.0).min(tilesy);
    (x0 as u32, x1 as u32, y0 as u32, y1 as u32)
}

/// Counts tile intersections per tile and fills the statistics rows `[V, 9]` (see `CullStats::to_counts`).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn count_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    tile_counts: &Tensor<Atomic<u32>>,
    stats: &Tensor<Atomic<i32>>,
    count: u32,
    views: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
) {
    let k = ABSOLUTE_POS;
    let count = count as usize;
    if k >= count * (views as usize) {
        terminate!();
    }
    let v = k / count;
    let row = 9 * v;
    stats[row].fetch_add(1i32);
    let reason = reasons[k];
    if reason != 0 {
        stats[row + 1 + reason as usize].fetch_add(1i32);
    } else {
        stats[row + 1].fetch_add(1i32);
        let (x0, x1, y0, y1) =
            tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], tile_size, tiles_x, tiles_y);
        let base = v * (tiles_x * tiles_y) as usize;
        for ty in y0..y1 {
            for tx in x0..x1 {
                tile_counts[base + (ty * tiles_x + tx) as usize].fetch_add(1u32);
            }
        }
        let touched = (x1 - x0) * (y1 - y0);
        stats[row + 8].fetch_add(touched as i32);
    }
}

/// Exclusive prefix sum of `counts` (length `len`) into `offsets` (length `len + 1`), in one cube of
/// [`SCAN_THREADS`] units: each unit sums a contiguous segment of `segment = ceil(len / SCAN_THREADS)` entries,
/// one unit scans the segment sums, then each unit writes its segment. `total[0]` receives the sum.
#[cube(launch)]
pub fn scan_kernel(counts: &Tensor<u32>, offsets: &mut Tensor<u32>, total: &mut Tensor<u32>, len: u32, segment: u32) {
    let mut partial = Shared::<[u32]>::new_slice(SCAN_LEN);
    let unit = UNIT_POS_X;
    let start = (unit * segment).min(len);
    let end = (start + segment).min(len);
    let mut sum = 0u32;
    for i in start..end {
        sum += counts[i as usize];
    }
    partial[unit as usize] = sum;
    sync_cube();
    if unit == 0 {
        let mut running = 0u32;
        for t in 0..SCAN_THREADS {
            let value = partial[t as usize];
            partial[t as usize] = running;
            running += value;
        }
        offsets[len as usize] = running;
        total[0] = running;
    }
    sync_cube();
    let mut running = partial[unit as usize];
    for i in start..end {
        offsets[i as usize] = running;
        running += counts[i as usize];
    }
}

/// Writes one sort entry per (kept Gaussian, tile it touches) into the list's slice of the intersection
/// buffer, in arrival order: the list index, the Gaussian's depth in that view and its index. The slot within
/// the slice does not matter, since [`bitonic_step_kernel`] orders the entries by all three afterwards.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn fill_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    depths: &Tensor<f32>,
    offsets: &Tensor<u32>,
    cursors: &Tensor<Atomic<u32>>,
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    count: u32,
    views: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
) {
    let k = ABSOLUTE_POS;
    let count = count as usize;
    if k >= count * (views as usize) {
        terminate!();
    }
    if reasons[k] == 0 {
        let v = k / count;
        let n = (k % count) as u32;
        let depth = depths[k];
        let (x0, x1, y0, y1) =
            tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], tile_size, tiles_x, tiles_y);
        let base = v * (tiles_x * tiles_y) as usize;
        for ty in y0..y1 {
            for tx in x0..x1 {
                let list = base + (ty * tiles_x + tx) as usize;
                let slot = (offsets[list] + cursors[list].fetch_add(1u32)) as usize;
                entry_lists[slot] = list as u32;
                entry_depths[slot] = depth;
                entry_ids[slot] = n;
            }
        }
    }
}

/// Marks the entries past the last intersection (the sort runs on a power-of-two length) with a list index
/// above every real one, so they sort to the end.
#[cube(launch)]
pub fn pad_kernel(
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    from: u32,
    len: u32,
) {
    let i = ABSOLUTE_POS as u32 + from;
    if i >= len {
        terminate!();
    }
    entry_lists[i as usize] = u32::MAX;
    entry_depths[i as usize] = 0.0;
    entry_ids[i as usize] = i;
}

/// Whether entry `a` goes before entry `b`: by list, then depth (front to back), then Gaussian index (the
/// host's order for equal depths). A strict total order, so the sorted result does not depend on the arrival
/// order the atomics of [`fill_kernel`] gave.
#[cube]
fn entry_before(list_a: u32, depth_a: f32, id_a: u32, list_b: u32, depth_b: f32, id_b: u32) -> bool {
    list_a < list_b || (list_a == list_b && (depth_a < depth_b || (depth_a == depth_b && id_a < id_b)))
}

/// One compare-and-exchange stage `(block, stride)` of a bitonic sort of all entries at once (every list of
/// every view), one unit per pair: `log2(len) · (log2(len) + 1) / 2` launches sort `len` (a power of two)
/// entries. Each unit does constant work, so no list length makes a unit run long.
#[cube(launch)]
pub fn bitonic_step_kernel(
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    block: u32,
    stride: u32,
    len: u32,
) {
    let pair = ABSOLUTE_POS as u32;
    if pair >= len / 2 {
        terminate!();
    }
    let low = (pair / stride) * 2 * stride + pair % stride;
    let high = low + stride;
    let ascending = (low & block) == 0;
    let (a, b) = (low as usize, high as usize);
    let (list_a, depth_a, id_a) = (entry_lists[a], entry_depths[a], entry_ids[a]);
    let (list_b, depth_b, id_b) = (entry_lists[b], entry_depths[b], entry_ids[b]);
    if entry_before(list_b, depth_b, id_b, list_a, depth_a, id_a) == ascending {
        entry_lists[a] = list_b;
        entry_depths[a] = depth_b;
        entry_ids[a] = id_b;
        entry_lists[b] = list_a;
        entry_depths[b] = depth_a;
        entry_ids[b] = id_a;
    }
}

/// Front-to-back compositing, one unit per pixel (`ABSOLUTE_POS_X/Y` the pixel, `ABSOLUTE_POS_Z` the view).
///
/// Writes the packed image `[V, H, W, K + 2]` (colours, alpha, expected depth), the final transmittance and the
/// list end per pixel.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn composite_kernel(
    ids: &Tensor<u32>,
    offsets: &Tensor<u32>,
    means2d: &Tensor<f32>,
    conics: &Tensor<f32>,
    depths: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    background: &Tensor<f32>,
    images: &mut Tensor<f32>,
    transmittances: &mut Tensor<f32>,
    list_ends: &mut Tensor<u32>,
    count: u32,
    per_view: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    #[comptime] channels: usize,
) {
    let x = ABSOLUTE_POS_X;
    let y = ABSOLUTE_POS_Y;
    let v = ABSOLUTE_POS_Z as usize;
    if x >= width || y >= height {
        terminate!();
    }
    let pixel = (v * height as usize + y as usize) * width as usize + x as usize;
    let list = v * (tiles_x * tiles_y) as usize + ((y / tile_size) * tiles_x + x / tile_size) as usize;
    let start = offsets[list] as usize;
    let end = offsets[list + 1] as usize;
    let base = v * count as usize;
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);

    let mut accumulated = Array::<f32>::new(channels);
    let mut depth = 0.0f32;
    let mut transmittance = 1.0f32;
    let mut last = 0u32;
    let mut j = start;
    loop {
        if j >= end {
            break;
        }
        let id = ids[j] as usize;
        let k = base + id;
        let mut opacity = opacities[id];
        if per_view == 1 {
            opacity = opacities[k];
        }
        let dx = means2d[2 * k] - px;
        let dy = means2d[2 * k + 1] - py;
        let (a, b, c) = (conics[3 * k], conics[3 * k + 1], conics[3 * k + 2]);
        let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        let alpha = (opacity * (-sigma).exp()).min(MAX_ALPHA);
        if !(sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD) {
            let next = transmittance * (1.0 - alpha);
            if next <= MIN_TRANSMITTANCE {
                break;
            }
            let weight = alpha * transmittance;
            for ch in 0..channels {
                accumulated[ch] += colors[id * channels + ch] * weight;
            }
            depth += depths[k] * weight;
            transmittance = next;
            last = (j - start + 1) as u32;
        }
        j += 1;
    }
    let alpha = 1.0 - transmittance;
    let out = pixel * (channels + 2);
    for ch in 0..channels {
        images[out + ch] = accumulated[ch] + transmittance * background[ch];
    }
    images[out + channels] = alpha;
    images[out + channels + 1] = depth / alpha.max(MIN_DEPTH_ALPHA);
    transmittances[pixel] = transmittance;
    list_ends[pixel] = last;
}

/// Backward of compositing, one unit per pixel: walks the pixel's list back to front from its end and adds
/// each footprint's gradient into one buffer holding, in this order, the per-(view, Gaussian) gradients of
/// `means2d [V, N, 2]`, `conics [V, N, 3]` and `depths [V, N]`, then the input gradients of the opacities
/// (`[N]` or `[V, N]`, starting at `opacity_offset`) and the colours (`[N, K]`, at `color_offset`). One buffer
/// keeps the kernel within the storage-buffer bindings every wgpu adapter offers.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn composite_backward_kernel<A: FloatAdd>(
    ids: &Tensor<u32>,
    offsets: &Tensor<u32>,
    means2d: &Tensor<f32>,
    conics: &Tensor<f32>,
    depths: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    background: &Tensor<f32>,
    images: &Tensor<f32>,
    transmittances: &Tensor<f32>,
    list_ends: &Tensor<u32>,
    grad_images: &Tensor<f32>,
    grads: &Tensor<Atomic<A::Slot>>,
    count: u32,
    views: u32,
    opacity_offset: u32,
    color_offset: u32,
    per_view: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    #[comptime] channels: usize,
) {
    let x = ABSOLUTE_POS_X;
    let y = ABSOLUTE_POS_Y;
    let v = ABSOLUTE_POS_Z as usize;
    if x >= width || y >= height {
        terminate!();
    }
    let pixel = (v * height as usize + y as usize) * width as usize + x as usize;
    let last = list_ends[pixel] as usize;
    if last == 0 {
        terminate!();
    }
    let list = v * (tiles_x * tiles_y) as usize + ((y / tile_size) * tiles_x + x / tile_size) as usize;
    let start = offsets[list] as usize;
    let base = v * count as usize;
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
    let packed = pixel * (channels + 2);
    let pairs = views as usize * count as usize;
    let conic_offset = 2 * pairs;
    let depth_offset = 5 * pairs;
    let opacity_offset = opacity_offset as usize;
    let color_offset = color_offset as usize;

    let final_transmittance = transmittances[pixel];
    let alpha_out = images[packed + channels];
    let depth_out = images[packed + channels + 1];
    let grad_depth_out = grad_images[packed + channels + 1];
    // depth = D / max(alpha, eps): dD = g / max(alpha, eps); dalpha -= g depth / alpha (unless clamped).
    let clamped_alpha = alpha_out.max(MIN_DEPTH_ALPHA);
    let grad_sum_depth = grad_depth_out / clamped_alpha;
    let mut grad_alpha_out = grad_images[packed + channels];
    if alpha_out >= MIN_DEPTH_ALPHA {
        grad_alpha_out -= grad_depth_out * depth_out / clamped_alpha;
    }
    let mut grad_final = -grad_alpha_out;
    for ch in 0..channels {
        grad_final += grad_images[packed + ch] * background[ch];
    }

    let mut behind = Array::<f32>::new(channels);
    let mut depth_behind = 0.0f32;
    let mut transmittance = final_transmittance;
    let mut j = start + last;
    loop {
        if j == start {
            break;
        }
        j -= 1;
        let id = ids[j] as usize;
        let k = base + id;
        let mut opacity = opacities[id];
        let mut opacity_slot = id;
        if per_view == 1 {
            opacity = opacities[k];
            opacity_slot = k;
        }
        let dx = means2d[2 * k] - px;
        let dy = means2d[2 * k + 1] - py;
        let (a, b, c) = (conics[3 * k], conics[3 * k + 1], conics[3 * k + 2]);
        let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        let falloff = (-sigma).exp();
        let raw = opacity * falloff;
        let alpha = raw.min(MAX_ALPHA);
        if !(sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD) {
            let remaining = 1.0 - alpha;
            transmittance /= remaining;
            let weight = alpha * transmittance;
            let mut grad_alpha = 0.0f32;
            for ch in 0..channels {
                let color = colors[id * channels + ch];
                let g = grad_images[packed + ch];
                A::add(grads, color_offset + id * channels + ch, g * weight);
                grad_alpha += g * (color - behind[ch]);
                behind[ch] = alpha * color + remaining * behind[ch];
            }
            let depth = depths[k];
            A::add(grads, depth_offset + k, grad_sum_depth * weight);
            grad_alpha += grad_sum_depth * (depth - depth_behind);
            depth_behind = alpha * depth + remaining * depth_behind;
            grad_alpha = grad_alpha * transmittance - grad_final * final_transmittance / remaining;
            if raw <= MAX_ALPHA {
                A::add(grads, opacity_offset + opacity_slot, grad_alpha * falloff);
                // alpha = o exp(-sigma): dalpha/dsigma = -alpha.
                let grad_sigma = -grad_alpha * alpha;
                A::add(grads, conic_offset + 3 * k, grad_sigma * 0.5 * dx * dx);
                A::add(grads, conic_offset + 3 * k + 1, grad_sigma * dx * dy);
                A::add(grads, conic_offset + 3 * k + 2, grad_sigma * 0.5 * dy * dy);
                A::add(grads, 2 * k, grad_sigma * (a * dx + b * dy));
                A::add(grads, 2 * k + 1, grad_sigma * (b * dx + c * dy));
            }
        }
    }
}

/// `dL/du` for `R(u)` given `dL/dR` (rows), the quaternion `w x y z` treated as unconstrained.
#[cube]
fn rotation_backward(cov: Covariance, g: M3) -> (f32, f32, f32, f32) {
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
    count: u32,
    views: u32,
    width: u32,
    height: u32,
    eps2d: f32,
) {
    let n = ABSOLUTE_POS;
    let count = count as usize;
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
    let pairs = views as usize * count;
    for v in 0..views as usize {
        let k = v * count + n;
        if reasons[k] == 0 {
            let cam = camera(viewmats, intrinsics, v);
            let point = sum3(apply(cam.rotation, mean), cam.translation);
            let e = ewa(cov, cam, point, width as f32, height as f32, eps2d);
            let conic = 2 * pairs + 3 * k;
            let (ga, gb, gc) = (footprint_grads[conic], footprint_grads[conic + 1], footprint_grads[conic + 2]);
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

            let (x, y, z) = (point.x, point.y, point.z);
            let (fx, fy) = (cam.fx, cam.fy);
            let (tx, ty) = (e.tx, e.ty);
            let z2 = z * z;
            let z3 = z2 * z;
            let (gmx, gmy) = (footprint_grads[2 * k], footprint_grads[2 * k + 1]);
            let mut gpx = gmx * fx / z;
            let mut gpy = gmy * fy / z;
            let mut gpz = -(gmx * fx * x + gmy * fy * y) / z2 + footprint_grads[5 * pairs + k];
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
