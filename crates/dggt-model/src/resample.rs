//! PyTorch's antialiased bicubic resize (`interpolate(mode="bicubic", antialias=True, align_corners=False)`)
//! as explicit resampling matrices.
//!
//! The DINO positional embedding is resized with this kernel, and burn's bicubic `interpolate` follows the
//! classic (non-antialiased, a = -0.75) definition instead. The weights are computed on the host in `f64`, so
//! the result is exact and identical on every backend; applying them is a matrix product.
//!
//! Per output sample `i` along one axis, with `scale = in / out` (or `1 / scale_factor` when the resize was
//! asked for by a scale factor): centre `c = scale * (i + 0.5)`; support `2 * max(scale, 1)`; the taps are
//! the input samples `j` in `[trunc(c - support + 0.5), trunc(c + support + 0.5))` clipped to the input, with
//! weight `keys((j - c + 0.5) / max(scale, 1))` (Keys cubic, a = -0.5), normalised to sum to one. Upscaling is
//! therefore plain a = -0.5 bicubic whose border taps are dropped and renormalised rather than clamped.
//!
//! The DPT heads' bilinear resize with `align_corners = True` ([`bilinear_aligned`]) is built the same way, one
//! axis at a time: a product with the dense tap matrix for short axes, two gathers and a blend for long ones.
//! burn's CubeCL backends have no backward for bilinear `interpolate`, and both forms are differentiable on
//! every backend.

use burn::tensor::{Int, Tensor, TensorData};

use crate::constant::ConstantSite;

/// Keys' cubic convolution kernel with `a = -0.5`, the kernel of PyTorch's antialiased bicubic mode.
fn keys_cubic(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        (((x - 5.0) * x + 8.0) * x - 4.0) * A
    } else {
        0.0
    }
}

/// The input-per-output sampling step along one axis: `1 / scale_factor` when the resize is driven by a
/// scale factor, else `input / output`.
pub fn sampling_step(input: usize, output: usize, scale_factor: Option<f64>) -> f64 {
    match scale_factor {
        Some(factor) => 1.0 / factor,
        None => input as f64 / output as f64,
    }
}

/// Row-major `[output, input]` weights of a one-axis antialiased bicubic resize; every row sums to one.
pub fn antialiased_bicubic_weights(input: usize, output: usize, step: f64) -> Vec<f64> {
    let support = if step >= 1.0 { 2.0 * step } else { 2.0 };
    let inv_step = if step >= 1.0 { 1.0 / step } else { 1.0 };
    let mut weights = vec![0.0; output * input];
    for i in 0..output {
        let centre = step * (i as f64 + 0.5);
        // Truncation toward zero, then clipping, as PyTorch computes the window.
        let first = ((centre - support + 0.5) as i64).max(0) as usize;
        let end = ((centre + support + 0.5) as i64).clamp(0, input as i64) as usize;
        let row = &mut weights[i * input..(i + 1) * input];
        let mut total = 0.0;
        for (j, w) in row.iter_mut().enumerate().take(end).skip(first) {
            *w = keys_cubic((j as f64 - centre + 0.5) * inv_step);
            total += *w;
        }
        if total != 0.0 {
            row.iter_mut().for_each(|w| *w /= total);
        }
    }
    weights
}

/// Row-major `[out_h * out_w, in_h * in_w]` matrix of the separable 2D resize of a row-major grid: the
/// Kronecker product of the row and column matrices. `output = matrix · input` for `[in_h * in_w, C]` input.
pub fn antialiased_bicubic_matrix_2d(input: [usize; 2], output: [usize; 2], step: [f64; 2]) -> Vec<f32> {
    let rows = antialiased_bicubic_weights(input[0], output[0], step[0]);
    let cols = antialiased_bicubic_weights(input[1], output[1], step[1]);
    let (in_cells, out_cells) = (input[0] * input[1], output[0] * output[1]);
    let mut matrix = vec![0.0f32; out_cells * in_cells];
    for oy in 0..output[0] {
        for ox in 0..output[1] {
            let out_row = &mut matrix[(oy * output[1] + ox) * in_cells..][..in_cells];
            for iy in 0..input[0] {
                let wy = rows[oy * input[0] + iy];
                if wy == 0.0 {
                    continue;
                }
                for ix in 0..input[1] {
                    out_row[iy * input[1] + ix] = (wy * cols[ox * input[1] + ix]) as f32;
                }
            }
        }
    }
    matrix
}

/// Source taps of a one-axis bilinear resize with `align_corners = True`: output sample `i` reads input samples
/// `lower[i]` and `lower[i] + 1` (clamped) with weight `fraction[i]` on the upper one, at source coordinate
/// `i · (input - 1) / (output - 1)` (the scale in `f32`, as PyTorch computes it; 0 for one output sample).
fn bilinear_aligned_taps(input: usize, output: usize) -> (Vec<i64>, Vec<i64>, Vec<f32>) {
    let scale = if output > 1 { (input as f32 - 1.0) / (output as f32 - 1.0) } else { 0.0 };
    let mut taps = (Vec::with_capacity(output), Vec::with_capacity(output), Vec::with_capacity(output));
    for i in 0..output {
        let source = scale * i as f32;
        let lower = (source.floor() as usize).min(input - 1);
        taps.0.push(lower as i64);
        taps.1.push((lower + 1).min(input - 1) as i64);
        taps.2.push(source - lower as f32);
    }
    taps
}

/// Axes at most this long are resized by a product with the dense `[input, output]` tap matrix (at most this
/// many multiply-adds per output sample, all in the matrix kernels, forward and backward); longer ones by two
/// gathers, whose backward is a scatter (single-threaded on the CPU backends).
const DENSE_RESIZE_MAX_INPUT: usize = 64;

/// Resizes axis `axis` (2: height, 3: width) of `x` to `output` samples, bilinearly with `align_corners = True`.
fn bilinear_aligned_axis(x: Tensor<4>, axis: usize, output: usize) -> Tensor<4> {
    let input = x.dims()[axis];
    if input == output {
        return x;
    }
    let (lower, upper, fraction) = bilinear_aligned_taps(input, output);
    if input <= DENSE_RESIZE_MAX_INPUT {
        return dense_resize_axis(x, axis, (&lower, &upper, &fraction));
    }
    gathered_resize_axis(x, axis, (lower, upper, fraction))
}

/// The resize as two gathers (each output sample's taps below and above) and a blend by the fractions.
fn gathered_resize_axis(
    x: Tensor<4>,
    axis: usize,
    (lower, upper, fraction): (Vec<i64>, Vec<i64>, Vec<f32>),
) -> Tensor<4> {
    let device = x.device();
    let output = lower.len();
    let index = |taps: Vec<i64>| Tensor::<1, Int>::from_data(TensorData::new(taps, [output]), &device);
    let mut shape = [1; 4];
    shape[axis] = output;
    let fraction = ConstantSite::like(&x).tensor(fraction, [output]).reshape(shape);
    let below = x.clone().select(axis, index(lower));
    let above = x.select(axis, index(upper));
    below.clone() + (above - below) * fraction
}

/// The resize as a product with the dense tap matrix: output sample `i` weighs input `lower[i]` by
/// `1 - fraction[i]` and `upper[i]` by `fraction[i]`.
fn dense_resize_axis(x: Tensor<4>, axis: usize, (lower, upper, fraction): (&[i64], &[i64], &[f32])) -> Tensor<4> {
    let input = x.dims()[axis];
    let output = lower.len();
    let mut matrix = vec![0.0f32; input * output];
    // Width: x [.., W] · M [W, W']; height: M [H', H] · x [.., H, W].
    let cell = |source: i64, target: usize| match axis {
        3 => source as usize * output + target,
        _ => target * input + source as usize,
    };
    for (i, ((&lo, &up), &f)) in lower.iter().zip(upper).zip(fraction).enumerate() {
        matrix[cell(lo, i)] += 1.0 - f;
        matrix[cell(up, i)] += f;
    }
    let site = ConstantSite::like(&x);
    match axis {
        3 => x.matmul(site.tensor(matrix, [1, 1, input, output])),
        _ => site.tensor(matrix, [1, 1, output, input]).matmul(x),
    }
}

/// `[B, C, H, W]` resized to `size = [height, width]` like PyTorch's
/// `interpolate(mode="bilinear", align_corners=True)`: along the width, then along the height (the 2D
/// interpolation is separable, so this is the same weighted sum of the four neighbours).
pub fn bilinear_aligned(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    let [_, _, height, width] = x.dims();
    assert!(height > 0 && width > 0 && size[0] > 0 && size[1] > 0, "bilinear resize of an empty map");
    bilinear_aligned_axis(bilinear_aligned_axis(x, 3, size[1]), 2, size[0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;
    use burn::tensor::module::interpolate;
    use burn::tensor::ops::{InterpolateMode, InterpolateOptions};

    #[test]
    fn bilinear_aligned_matches_the_backend_interpolation_and_has_a_gradient() {
        let device = Device::flex().autodiff();
        let values: Vec<f32> = (0..2 * 3 * 5 * 7).map(|i| ((i * 37) % 101) as f32 / 101.0 - 0.5).collect();
        let x = Tensor::<4>::from_data(TensorData::new(values, [2, 3, 5, 7]), &device).require_grad();
        for size in [[10, 14], [5, 7], [3, 4], [1, 1], [9, 2], [56, 70]] {
            let ours = bilinear_aligned(x.clone(), size);
            let options = InterpolateOptions::new(InterpolateMode::Bilinear).with_align_corners(true);
            let reference = interpolate(x.clone(), options.with_output_size(size));
            assert_eq!(ours.dims(), reference.dims());
            let difference: f32 = (ours.clone() - reference).abs().max().into_scalar();
            assert!(difference < 1e-6, "{size:?}: differs by {difference}");
            let grad = ours.sum().backward();
            let grad = x.grad(&grad).expect("a gradient").into_data().try_to_vec::<f32>().unwrap();
            // Each output sample's weights sum to one, so the input gradients sum to the output count.
            let (total, expected) = (grad.iter().map(|&g| f64::from(g)).sum::<f64>(), (6 * size[0] * size[1]) as f64);
            assert!((total - expected).abs() < 1e-5 * expected, "{size:?}: {total}");
        }
    }

    #[test]
    fn the_dense_and_gathered_resizes_agree_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        for (shape, size) in [([8, 16, 4, 6], [42, 56]), ([3, 32, 12, 16], [24, 32]), ([1, 4, 30, 40], [7, 9])] {
            let count = shape.iter().product::<usize>();
            let values: Vec<f32> = (0..count).map(|i| ((i * 7919) % 1009) as f32 / 1009.0 - 0.5).collect();
            let x = Tensor::<4>::from_data(TensorData::new(values, shape), &device).require_grad();
            let weights = Tensor::<4>::random(
                [shape[0], shape[1], size[0], size[1]],
                burn::tensor::Distribution::Normal(0.0, 1.0),
                &device,
            );
            let resize = |dense: bool| {
                let mut y = x.clone();
                for (axis, output) in [(3, size[1]), (2, size[0])] {
                    let taps = bilinear_aligned_taps(y.dims()[axis], output);
                    y = if dense {
                        dense_resize_axis(y, axis, (&taps.0, &taps.1, &taps.2))
                    } else {
                        gathered_resize_axis(y, axis, taps)
                    };
                }
                let grads = (y.clone() * weights.clone()).sum().backward();
                (
                    y.into_data().try_to_vec::<f32>().unwrap(),
                    x.grad(&grads).unwrap().into_data().try_to_vec::<f32>().unwrap(),
                )
            };
            let (dense, dense_grad) = resize(true);
            let (gathered, gathered_grad) = resize(false);
            let worst = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
            assert!(worst(&dense, &gathered) < 1e-5, "{shape:?}: values differ by {}", worst(&dense, &gathered));
            assert!(
                worst(&dense_grad, &gathered_grad) < 1e-4,
                "{shape:?}: gradients differ by {}",
                worst(&dense_grad, &gathered_grad)
            );
        }
    }

    #[test]
    fn same_size_is_identity() {
        let w = antialiased_bicubic_weights(4, 4, 1.0);
        for i in 0..4 {
            for j in 0..4 {
                assert_eq!(w[i * 4 + j], if i == j { 1.0 } else { 0.0 });
            }
        }
    }

    #[test]
    fn rows_sum_to_one() {
        for (input, output) in [(4, 5), (37, 25), (37, 37), (16, 3), (3, 16)] {
            let w = antialiased_bicubic_weights(input, output, sampling_step(input, output, None));
            for row in w.chunks(input) {
                assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn downscaling_widens_support() {
        // Halving: each output sample averages 8 taps (support 4 on each side in input units), clipped at borders.
        let w = antialiased_bicubic_weights(16, 8, 2.0);
        let taps = |i: usize| w[i * 16..(i + 1) * 16].iter().filter(|&&x| x != 0.0).count();
        assert_eq!(taps(4), 8);
        assert!(taps(0) < 8);
    }

    #[test]
    fn constant_is_preserved_in_2d() {
        let m = antialiased_bicubic_matrix_2d([4, 4], [3, 7], [4.0 / 3.0, 4.0 / 7.0]);
        for row in m.chunks(16) {
            assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
    }
}
