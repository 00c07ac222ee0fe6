//! Hash-based value noise for procedural textures.
//!
//! Every value is a pure function of the integer lattice coordinates and a salt, so shading a point never depends
//! on what was shaded before or on which thread shades it: images are reproducible bit for bit.

use dggt_geom::glam::{DVec2, DVec3};

/// A 64-bit finaliser with good avalanche (every input bit affects every output bit).
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform value in `[0, 1)` for lattice cell `(i, j, k)`.
pub(crate) fn hash_unit(salt: u64, i: i64, j: i64, k: i64) -> f64 {
    let h = mix64(salt ^ mix64((i as u64) ^ mix64((j as u64) ^ mix64((k as u64).wrapping_add(0x9e37_79b9_7f4a_7c15)))));
    (h >> 11) as f64 / (1u64 << 53) as f64
}

fn fade(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Smoothly interpolated lattice noise in the plane, values in `[0, 1)`.
pub(crate) fn value2(salt: u64, p: DVec2) -> f64 {
    let (fx, fy) = (p.x.floor(), p.y.floor());
    let (i, j) = (fx as i64, fy as i64);
    let (tx, ty) = (fade(p.x - fx), fade(p.y - fy));
    let at = |di: i64, dj: i64| hash_unit(salt, i + di, j + dj, 0);
    lerp(lerp(at(0, 0), at(1, 0), tx), lerp(at(0, 1), at(1, 1), tx), ty)
}

/// Smoothly interpolated lattice noise in space, values in `[0, 1)`.
pub(crate) fn value3(salt: u64, p: DVec3) -> f64 {
    let f = p.floor();
    let (i, j, k) = (f.x as i64, f.y as i64, f.z as i64);
    let t = p - f;
    let (tx, ty, tz) = (fade(t.x), fade(t.y), fade(t.z));
    let at = |di: i64, dj: i64, dk: i64| hash_unit(salt, i + di, j + dj, k + dk);
    let plane = |dk: i64| lerp(lerp(at(0, 0, dk), at(1, 0, dk), tx), lerp(at(0, 1, dk), at(1, 1, dk), tx), ty);
    lerp(plane(0), plane(1), tz)
}

/// Fractal sum of `octaves` planar noise layers (each twice the frequency and half the weight of the previous
/// one), normalised back to `[0, 1)`.
pub(crate) fn fbm2(salt: u64, p: DVec2, octaves: u32) -> f64 {
    let (mut sum, mut weight, mut total, mut scale) = (0.0, 1.0, 0.0, 1.0);
    for octave in 0..octaves {
        sum += weight * value2(salt.wrapping_add(octave as u64), p * scale);
        total += weight;
        weight *= 0.5;
        scale *= 2.03;
    }
    sum / total
}

/// Hermite step from 0 at `edge0` to 1 at `edge1`.
pub(crate) fn smoothstep(edge0: f64, edge1: f64, x: f64) -> f64 {
    let t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_continuous_and_salted() {
        let mut previous = value2(7, DVec2::new(0.0, 0.3));
        for step in 1..2000 {
            let p = DVec2::new(step as f64 * 0.001, 0.3);
            let v = value2(7, p);
            assert!((0.0..1.0).contains(&v));
            assert!((v - previous).abs() < 0.01, "jump at {p}");
            previous = v;
        }
        assert_ne!(value2(1, DVec2::new(0.5, 0.5)), value2(2, DVec2::new(0.5, 0.5)));
        let f = fbm2(3, DVec2::new(-12.7, 4.1), 4);
        assert!((0.0..1.0).contains(&f));
        assert!((0.0..1.0).contains(&value3(5, DVec3::new(-3.2, 0.1, 9.9))));
    }
}
