//! The exact (erf) GELU and its slope for the fused host op, with an `erf` fast enough to run per neighbour and
//! channel: Abramowitz and Stegun's 7.1.26, `erfc(x) ~ (a1 t + ... + a5 t^5) exp(-x^2)`, `t = 1 / (1 + p x)`
//! for `x >= 0`, absolute error at most 1.5e-7 (about two f32 steps near 1). Its `exp(-x^2)` at `x = z / sqrt(2)`
//! is also the Gaussian density the slope needs, so value and slope cost one `exp`, itself a short polynomial
//! ([`exp_non_positive`]) so that a loop over channels vectorises.
//!
//! `GELU(z) = z Phi(z)` and `GELU'(z) = Phi(z) + z phi(z)`, with `Phi(z) = erfc(-z / sqrt 2) / 2`: for negative
//! `z` the tail is used directly, with no cancellation against 1. A NaN passes through.

/// 7.1.26's constants, shared with the GPU kernel's GELU (`cube::kernels`).
pub(crate) const P: f32 = 0.327_591_1;
pub(crate) const A1: f32 = 0.254_829_6;
pub(crate) const A2: f32 = -0.284_496_74;
pub(crate) const A3: f32 = 1.421_413_7;
pub(crate) const A4: f32 = -1.453_152;
pub(crate) const A5: f32 = 1.061_405_4;
/// `1 / sqrt(2 pi)`.
pub(crate) const INV_SQRT_TAU: f32 = 0.398_942_3;

/// `exp(x)` for `x <= 0`, within two f32 steps: `2^n e^t` with `n` the integer nearest `x log2(e)` (set as the
/// exponent's bits) and `t = x - n ln 2` (`|t| <= ln(2) / 2`, `ln 2` in two parts so that `t` is exact to f32),
/// `e^t` from its Taylor series to degree 7 (remainder below 5e-9). Zero below `2^-126`; a NaN passes through.
#[inline]
pub fn exp_non_positive(x: f32) -> f32 {
    /// `1.5 x 2^23`: adding and subtracting it rounds an f32 of magnitude below `2^22` to the nearest integer.
    const ROUND: f32 = 12_582_912.0;
    /// `ln 2` split: the high part has 16 significant bits, so `n LN2_HIGH` is exact for `|n| <= 127`.
    const LN2_HIGH: f32 = 0.693_145_75;
    const LN2_LOW: f32 = 1.428_606_8e-6;
    let y = x * std::f32::consts::LOG2_E;
    let n = (y + ROUND) - ROUND;
    let t = (x - n * LN2_HIGH) - n * LN2_LOW;
    let mut power = 1.0 / 5040.0;
    for coefficient in [1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
        power = power * t + coefficient;
    }
    // The biased exponent `n + 127` read from the low mantissa bits of `n + 127 + ROUND` (no float-to-integer
    // conversion, which would not vectorise).
    let biased = (n.max(-126.0) + (127.0 + ROUND)).to_bits() - ROUND.to_bits();
    let scale = f32::from_bits(biased << 23);
    if y < -126.0 { 0.0 } else { power * scale }
}

/// `(Phi(z), phi(z))`: the standard normal distribution and density at `z`.
#[inline]
fn normal(z: f32) -> (f32, f32) {
    let x = z.abs() * std::f32::consts::FRAC_1_SQRT_2;
    let density = exp_non_positive(-x * x);
    let t = 1.0 / (1.0 + P * x);
    let polynomial = t * (A1 + t * (A2 + t * (A3 + t * (A4 + t * A5))));
    let tail = 0.5 * polynomial * density;
    let distribution = if z >= 0.0 { 1.0 - tail } else { tail };
    (distribution, INV_SQRT_TAU * density)
}

#[inline]
pub fn gelu(z: f32) -> f32 {
    z * normal(z).0
}

/// `(GELU(z), GELU'(z))`.
#[inline]
pub fn gelu_and_slope(z: f32) -> (f32, f32) {
    let (distribution, density) = normal(z);
    (z * distribution, distribution + z * density)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, Tensor, TensorData};

    /// A grid over `[-12, 12]` and a few extremes.
    fn grid() -> Vec<f32> {
        let mut z: Vec<f32> = (-2400..=2400).map(|i| i as f32 * 0.005).collect();
        z.extend([-1e4, -40.0, 40.0, 1e4, 0.0, -0.0]);
        z
    }

    #[test]
    fn exp_matches_the_standard_library() {
        let mut x: Vec<f32> = (0..=20_000).map(|i| -(i as f32) * 0.005).collect();
        x.extend([-87.0, -87.5, -88.0, -100.0, -1e4, f32::NEG_INFINITY, -0.0]);
        for x in x {
            let (found, expected) = (exp_non_positive(x), x.exp());
            let step = f32::EPSILON * expected;
            let bound = if expected < f32::MIN_POSITIVE { f32::MIN_POSITIVE } else { 2.0 * step };
            assert!((found - expected).abs() <= bound, "exp({x}) = {found}, expected {expected}");
        }
        assert!(exp_non_positive(f32::NAN).is_nan());
    }

    /// Within two f32 steps of the exact value (f64), and of burn's GELU (which `crate::head`'s tensor path uses).
    #[test]
    fn gelu_matches_the_exact_gelu_and_burns() {
        let z = grid();
        let reference = Tensor::<1>::from_data(TensorData::new(z.clone(), [z.len()]), &Device::flex());
        let reference = burn::tensor::activation::gelu(reference).try_into_vec_as::<f32>().unwrap();
        for (z, burns) in z.iter().zip(reference) {
            let found = gelu(*z);
            let exact = exact_gelu(*z as f64);
            let bound = z.abs().max(1.0) as f64;
            assert!((found as f64 - exact).abs() <= 2e-7 * bound, "GELU({z}) = {found}, exactly {exact}");
            assert!((found - burns).abs() as f64 <= 1e-6 * bound, "GELU({z}) = {found}, burn {burns}");
        }
    }

    #[test]
    fn the_slope_matches_a_central_difference() {
        for z in grid().into_iter().filter(|z| z.abs() <= 12.0) {
            let h = 1e-3f64;
            let expected = (exact_gelu(z as f64 + h) - exact_gelu(z as f64 - h)) / (2.0 * h);
            let found = gelu_and_slope(z).1 as f64;
            assert!((found - expected).abs() <= 1e-6, "GELU'({z}) = {found}, expected {expected}");
        }
        assert!(gelu_and_slope(f32::NAN).0.is_nan() && gelu_and_slope(f32::NAN).1.is_nan());
    }

    fn exact_gelu(z: f64) -> f64 {
        z * 0.5 * (1.0 + erf_f64(z / std::f64::consts::SQRT_2))
    }

    /// `erf` in f64 from its series (|x| < 3) and continued fraction (beyond), to ~1e-13.
    fn erf_f64(x: f64) -> f64 {
        let a = x.abs();
        let value = if a < 3.0 {
            let (mut term, mut sum, mut n) = (a, a, 0.0);
            while term.abs() > 1e-17 * sum.abs() {
                n += 1.0;
                term *= -a * a / n;
                sum += term / (2.0 * n + 1.0);
            }
            2.0 / std::f64::consts::PI.sqrt() * sum
        } else {
            let mut fraction = 0.0;
            for n in (1..60).rev() {
                fraction = n as f64 / 2.0 / (a + fraction);
            }
            1.0 - (-a * a).exp() / std::f64::consts::PI.sqrt() / (a + fraction)
        };
        value.copysign(x)
    }
}
