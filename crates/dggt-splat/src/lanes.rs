//! A block of pixels as SIMD lanes: the compositor evaluates one footprint at the 16 pixels of a 4x4 block at
//! once, with plain loops over fixed-size arrays that the compiler turns into vector instructions.
//!
//! Two things make those loops vectorise and keep them bit-identical on every processor:
//! - [`exp_neg`], an `f32` exponential written as range reduction and a polynomial (no call into libm, which
//!   would stop vectorisation and whose last bit differs between its CPU variants). Error at most 2 ulp.
//! - [`has_wide_vectors`], which picks a copy of the lane loops compiled for AVX2 where the processor has it
//!   (the baseline `x86_64` target has 4-lane SSE2). Rust never fuses a multiply and an add on its own, so both
//!   copies round every operation alike and give the same bits.

use crate::blocks::BLOCK;

/// Pixels per block, one lane each: lane `l` is the pixel at `(l % BLOCK, l / BLOCK)` of its block.
pub(crate) const LANES: usize = BLOCK * BLOCK;

/// One value per pixel of a block.
pub(crate) type Lanes<T> = [T; LANES];

/// Below this `exp` is under `f32`'s smallest normal; [`exp_neg`] clamps its argument there.
const MIN_EXPONENT: f32 = -87.0;

/// `exp(x)` for `x <= 0` (arguments below -87 and NaN give `exp(-87)`, positive ones `1`).
///
/// `x = k ln 2 + r` with `k` the nearest integer to `x / ln 2` and `|r| <= ln 2 / 2` (`ln 2` split in two
/// parts so that `k ln2_high` is exact), then `exp(r)` by a degree-6 polynomial and `2^k` from the exponent bits.
#[inline(always)]
pub(crate) fn exp_neg(x: f32) -> f32 {
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    const LN2_HIGH: f32 = 0.693_359_4;
    const LN2_LOW: f32 = -2.121_944_4e-4;
    // Adding 1.5 * 2^23 rounds to the nearest integer and leaves it in the low mantissa bits.
    const ROUNDER: f32 = 12_582_912.0;
    // Not `clamp`, which keeps a NaN: a NaN becomes -87 here, so that no lane computes garbage exponent bits.
    #[allow(clippy::manual_clamp)]
    let x = x.max(MIN_EXPONENT).min(0.0);
    let shifted = x * LOG2_E + ROUNDER;
    let k = shifted - ROUNDER;
    let k_int = shifted.to_bits() as i32 - ROUNDER.to_bits() as i32;
    let r = (x - k * LN2_HIGH) - k * LN2_LOW;
    // Taylor-like coefficients fitted on [-ln 2 / 2, ln 2 / 2].
    let mut p = 1.987_569_1e-4;
    p = p * r + 1.398_2e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let exp_r = p * r * r + r + 1.0;
    let scale = f32::from_bits(((k_int + 127) as u32) << 23);
    exp_r * scale
}

/// Whether the processor has AVX2: the compositor's entry points then run a copy of their lane loops compiled
/// for it (`#[target_feature(enable = "avx2")]` on the entry, `#[inline(always)]` on everything below it).
#[inline]
pub(crate) fn has_wide_vectors() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f32, b: f32) -> u32 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32
    }

    #[test]
    fn exp_neg_is_within_two_ulp_of_the_exact_exponential() {
        let mut worst = 0;
        // Every 997th float between -0 and -87 (negative floats' bits grow with their magnitude).
        let (smallest, largest) = ((-0.0f32).to_bits(), (-87.0f32).to_bits());
        let mut checked = 0;
        for bits in (smallest..=largest).step_by(997).chain([largest, smallest + 1]) {
            let x = f32::from_bits(bits);
            let exact = (f64::from(x)).exp() as f32;
            let got = exp_neg(x);
            worst = worst.max(ulps(got, exact));
            assert!(ulps(got, exact) <= 2, "exp({x}) = {got}, exactly {exact}");
            checked += 1;
        }
        assert!(checked > 1_000_000, "{checked}");
        assert!(worst >= 1, "a polynomial that is never off by one ulp was not tested");
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(exp_neg(-1e30), exp_neg(-87.0));
        assert_eq!(exp_neg(f32::NEG_INFINITY), exp_neg(-87.0));
        assert_eq!(exp_neg(3.0), 1.0);
        assert_eq!(exp_neg(f32::NAN), exp_neg(-87.0));
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn exp_neg_avx2(inputs: &[f32]) -> Vec<u32> {
        inputs.iter().map(|&x| exp_neg(x).to_bits()).collect()
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn both_vector_widths_give_the_same_bits() {
        assert!(has_wide_vectors(), "this test needs a processor with AVX2");
        let inputs: Vec<f32> = (0..4096).map(|i| -(i as f32) * 0.0021).collect();
        let scalar: Vec<u32> = inputs.iter().map(|&x| exp_neg(x).to_bits()).collect();
        // SAFETY: the processor supports AVX2 (asserted above).
        assert_eq!(scalar, unsafe { exp_neg_avx2(&inputs) });
    }
}
