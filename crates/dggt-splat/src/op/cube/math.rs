//! Device math shared by the kernels: 3-vectors and 3x3 matrices, finiteness, the rotation of a `w x y z`
//! quaternion. (The float addition the backward kernels accumulate gradients with is `dggt_cube::atomic`.)

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// A 3-vector.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct V3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

/// A 3x3 matrix as rows.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct M3 {
    pub r0: V3,
    pub r1: V3,
    pub r2: V3,
}

#[cube]
pub fn v3(x: f32, y: f32, z: f32) -> V3 {
    V3 { x, y, z }
}

#[cube]
pub fn dot(a: V3, b: V3) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

#[cube]
pub fn scaled(a: V3, s: f32) -> V3 {
    v3(a.x * s, a.y * s, a.z * s)
}

#[cube]
pub fn sum3(a: V3, b: V3) -> V3 {
    v3(a.x + b.x, a.y + b.y, a.z + b.z)
}

#[cube]
pub fn cross(a: V3, b: V3) -> V3 {
    v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)
}

#[cube]
pub fn transpose(m: M3) -> M3 {
    M3 { r0: v3(m.r0.x, m.r1.x, m.r2.x), r1: v3(m.r0.y, m.r1.y, m.r2.y), r2: v3(m.r0.z, m.r1.z, m.r2.z) }
}

/// `m v`.
#[cube]
pub fn apply(m: M3, v: V3) -> V3 {
    v3(dot(m.r0, v), dot(m.r1, v), dot(m.r2, v))
}

/// `a b`.
#[cube]
pub fn product(a: M3, b: M3) -> M3 {
    let bt = transpose(b);
    M3 { r0: apply(bt, a.r0), r1: apply(bt, a.r1), r2: apply(bt, a.r2) }
}

/// `a bᵀ`.
#[cube]
pub fn outer(a: V3, b: V3) -> M3 {
    M3 { r0: scaled(b, a.x), r1: scaled(b, a.y), r2: scaled(b, a.z) }
}

#[cube]
pub fn mat_sum(a: M3, b: M3) -> M3 {
    M3 { r0: sum3(a.r0, b.r0), r1: sum3(a.r1, b.r1), r2: sum3(a.r2, b.r2) }
}

#[cube]
pub fn mat_scaled(a: M3, s: f32) -> M3 {
    M3 { r0: scaled(a.r0, s), r1: scaled(a.r1, s), r2: scaled(a.r2, s) }
}

/// `m diag(s)`.
#[cube]
pub fn scale_columns(m: M3, s: V3) -> M3 {
    M3 {
        r0: v3(m.r0.x * s.x, m.r0.y * s.y, m.r0.z * s.z),
        r1: v3(m.r1.x * s.x, m.r1.y * s.y, m.r1.z * s.z),
        r2: v3(m.r2.x * s.x, m.r2.y * s.y, m.r2.z * s.z),
    }
}

#[cube]
pub fn finite(x: f32) -> bool {
    !(x.is_nan() || x.is_inf())
}

/// Rotation matrix of the unit quaternion `w x y z`.
#[cube]
pub fn rotation(w: f32, x: f32, y: f32, z: f32) -> M3 {
    M3 {
        r0: v3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
        r1: v3(2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
        r2: v3(2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)),
    }
}
