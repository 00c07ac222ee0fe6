//! The 3x3 convolution (stride 1, zero padding 1) on host buffers, as nine shifted matrix products.
//!
//! Each image is copied once into a zero-padded buffer `[C, H + 2, W + 2]` (plus [`TAIL`] zeros). In that
//! buffer, tap `(ky, kx)` of every output pixel `(i, j)` reads flat index `c·Hp·Wp + (i + ky)·Wp + (j + kx)`: for
//! a fixed tap this is the output's flat index `p = i·Wp + j` plus a constant, so the operand of each tap is a
//! plain strided matrix `[C, H·Wp]` over the padded buffer, with no im2col copy. Outputs are computed in that
//! padded-width layout `[O, H, Wp]`, whose last two columns of each row are junk and are dropped (forward) or
//! held at zero (backward, so they contribute nothing).
//!
//! - forward: `Y = Σ_k W_k · X_k` (`W_k = weight[:, :, ky, kx]`, `[O, C]`), then the bias;
//! - input gradient: `dXpad[:, p + off_k] += W_kᵀ · dY` for each tap, then the interior of `dXpad`;
//! - weight gradient: `dW_k = Σ_n dY_n · X_{k,n}ᵀ`; the bias gradient sums `dY` over images and pixels.
//!
//! Both gradients read `dY` with its values below [`FLUSH_BELOW`] (2⁻¹⁰⁰, subnormal products otherwise) as zero.
//!
//! Images run in parallel (rayon), each product single-threaded: the products are small (`O, C <= 64` in the
//! DPT heads at training sizes) and the images many. All buffers are `f32`, `NCHW`, weights `[O, C, 3, 3]`.

use gemm::{Parallelism, gemm};
use rayon::prelude::*;

/// Zeros after the padded image: the junk columns of the last row read up to two values past it.
const TAIL: usize = 2;

/// Output-gradient values smaller than this in magnitude (2⁻¹⁰⁰) are taken as zero by the backward pass.
///
/// Late in training the heads' output gradients hold subnormal floats, and an x86 processor multiplies those
/// through a microcode assist many times slower than a normal product: the input gradient's products, which do
/// the forward's work, took six times its time. No value this small can move anything: AdamW divides by at
/// least its ε (1e-8), and beside gradients of ordinary size it is below `f32`'s rounding.
const FLUSH_BELOW: f32 = 1.0 / (1u128 << 100) as f32;

/// Sizes of one call: `images` of `channels` x `height` x `width` in, `outputs` channels out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvShape {
    pub images: usize,
    pub channels: usize,
    pub outputs: usize,
    pub height: usize,
    pub width: usize,
}

impl ConvShape {
    fn padded_width(&self) -> usize {
        self.width + 2
    }

    /// Values of one padded image, tail included.
    fn padded_len(&self) -> usize {
        self.channels * self.plane() + TAIL
    }

    /// Values of one padded channel.
    fn plane(&self) -> usize {
        (self.height + 2) * self.padded_width()
    }

    /// Output pixels per channel in the padded-width layout.
    fn wide_pixels(&self) -> usize {
        self.height * self.padded_width()
    }

    /// Flat offset of tap `k` (`ky · 3 + kx`) in a padded channel.
    fn tap_offset(&self, k: usize) -> usize {
        (k / 3) * self.padded_width() + k % 3
    }

    fn input_len(&self) -> usize {
        self.images * self.channels * self.height * self.width
    }

    fn output_len(&self) -> usize {
        self.images * self.outputs * self.height * self.width
    }

    fn weight_len(&self) -> usize {
        self.outputs * self.channels * 9
    }
}

/// A strided view of a matrix in a slice: element `(r, c)` at `offset + r·row_stride + c·col_stride`.
#[derive(Debug, Clone, Copy)]
struct Strided {
    offset: usize,
    row_stride: usize,
    col_stride: usize,
}

impl Strided {
    /// The index one past the last element of a `rows` x `cols` matrix (both non-zero).
    fn end(&self, rows: usize, cols: usize) -> usize {
        self.offset + (rows - 1) * self.row_stride + (cols - 1) * self.col_stride + 1
    }
}

/// How one image's products share the threads: alone when the images alone occupy every thread.
fn parallelism(shape: &ConvShape) -> Parallelism {
    if shape.images >= rayon::current_num_threads() { Parallelism::None } else { Parallelism::Rayon(0) }
}

/// `dst (+)= lhs · rhs` for `lhs` `[m, k]` and `rhs` `[k, n]`, every matrix a strided view of its slice. The
/// views are checked against the slices' lengths, which is what makes the call into `gemm` sound.
#[allow(clippy::too_many_arguments)]
fn product(
    shape: &ConvShape,
    [m, n, k]: [usize; 3],
    dst: &mut [f32],
    dst_view: Strided,
    accumulate: bool,
    lhs: &[f32],
    lhs_view: Strided,
    rhs: &[f32],
    rhs_view: Strided,
) {
    if m == 0 || n == 0 || k == 0 {
        return;
    }
    assert!(dst_view.end(m, n) <= dst.len(), "conv3x3: destination view out of bounds");
    assert!(lhs_view.end(m, k) <= lhs.len(), "conv3x3: left operand view out of bounds");
    assert!(rhs_view.end(k, n) <= rhs.len(), "conv3x3: right operand view out of bounds");
    let stride = |s: usize| s as isize;
    // SAFETY: every element the views address lies inside its slice (checked above); `dst` is borrowed
    // mutably and does not alias the operands.
    unsafe {
        gemm(
            m,
            n,
            k,
            dst.as_mut_ptr().add(dst_view.offset),
            stride(dst_view.col_stride),
            stride(dst_view.row_stride),
            accumulate,
            lhs.as_ptr().add(lhs_view.offset),
            stride(lhs_view.col_stride),
            stride(lhs_view.row_stride),
            rhs.as_ptr().add(rhs_view.offset),
            stride(rhs_view.col_stride),
            stride(rhs_view.row_stride),
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism(shape),
        );
    }
}

/// One image `[C, H, W]` copied into the interior of a zeroed padded buffer.
fn pad_image(shape: &ConvShape, image: &[f32]) -> Vec<f32> {
    let (h, w, wp) = (shape.height, shape.width, shape.padded_width());
    let mut padded = vec![0.0f32; shape.padded_len()];
    for (c, channel) in image.chunks_exact(h * w).enumerate() {
        for (i, row) in channel.chunks_exact(w).enumerate() {
            let start = c * shape.plane() + (i + 1) * wp + 1;
            padded[start..start + w].copy_from_slice(row);
        }
    }
    padded
}

/// Tap `k`'s weights `[O, C]` (`weight[:, :, ky, kx]`) as a view of the `[O, C, 3, 3]` weights.
fn tap_weights(shape: &ConvShape, k: usize) -> Strided {
    Strided { offset: k, row_stride: shape.channels * 9, col_stride: 9 }
}

/// Tap `k`'s input operand `[C, H·Wp]` as a view of a padded image.
fn tap_input(shape: &ConvShape, k: usize) -> Strided {
    Strided { offset: shape.tap_offset(k), row_stride: shape.plane(), col_stride: 1 }
}

/// The output's padded-width layout `[O, H·Wp]`.
fn wide(shape: &ConvShape) -> Strided {
    Strided { offset: 0, row_stride: shape.wide_pixels(), col_stride: 1 }
}

/// An output gradient `[O, H, W]` spread into the padded-width layout, junk columns and values below
/// [`FLUSH_BELOW`] zero.
fn widen(shape: &ConvShape, grad: &[f32]) -> Vec<f32> {
    let (h, w, wp) = (shape.height, shape.width, shape.padded_width());
    let mut wide = vec![0.0f32; shape.outputs * shape.wide_pixels()];
    for (o, channel) in grad.chunks_exact(h * w).enumerate() {
        for (i, row) in channel.chunks_exact(w).enumerate() {
            let start = o * shape.wide_pixels() + i * wp;
            for (d, &v) in wide[start..start + w].iter_mut().zip(row) {
                *d = if v.abs() < FLUSH_BELOW { 0.0 } else { v };
            }
        }
    }
    wide
}

/// Checks the buffer lengths against `shape`.
fn check(shape: &ConvShape, buffers: &[(&str, usize, usize)]) {
    for &(what, len, expected) in buffers {
        assert_eq!(len, expected, "conv3x3: `{what}` holds {len} values, {shape:?} needs {expected}");
    }
}

/// `[N, O, H, W]` outputs of `input` `[N, C, H, W]` with `weight` `[O, C, 3, 3]` and `bias` `[O]`.
pub fn forward(shape: ConvShape, input: &[f32], weight: &[f32], bias: Option<&[f32]>) -> Vec<f32> {
    check(&shape, &[("input", input.len(), shape.input_len()), ("weight", weight.len(), shape.weight_len())]);
    if let Some(bias) = bias {
        check(&shape, &[("bias", bias.len(), shape.outputs)]);
    }
    let (h, w, wp) = (shape.height, shape.width, shape.padded_width());
    let image_in = shape.channels * h * w;
    let image_out = shape.outputs * h * w;
    let mut output = vec![0.0f32; shape.output_len()];
    if image_in == 0 || image_out == 0 {
        return output;
    }
    output.par_chunks_mut(image_out).zip(input.par_chunks(image_in)).for_each(|(out, image)| {
        let padded = pad_image(&shape, image);
        let mut wide_out = vec![0.0f32; shape.outputs * shape.wide_pixels()];
        for k in 0..9 {
            let dims = [shape.outputs, shape.wide_pixels(), shape.channels];
            product(
                &shape,
                dims,
                &mut wide_out,
                wide(&shape),
                k > 0,
                weight,
                tap_weights(&shape, k),
                &padded,
                tap_input(&shape, k),
            );
        }
        for (o, channel) in out.chunks_exact_mut(h * w).enumerate() {
            let b = bias.map_or(0.0, |b| b[o]);
            for (i, row) in channel.chunks_exact_mut(w).enumerate() {
                let start = o * shape.wide_pixels() + i * wp;
                for (y, &v) in row.iter_mut().zip(&wide_out[start..start + w]) {
                    *y = v + b;
                }
            }
        }
    });
    output
}

/// Gradients of [`forward`]'s input `[N, C, H, W]`, weight `[O, C, 3, 3]` and bias `[O]` given the output
/// gradient `[N, O, H, W]`.
pub struct ConvGrads {
    pub input: Vec<f32>,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

/// The backward pass of [`forward`].
pub fn backward(shape: ConvShape, input: &[f32], weight: &[f32], grad_output: &[f32]) -> ConvGrads {
    check(
        &shape,
        &[
            ("input", input.len(), shape.input_len()),
            ("weight", weight.len(), shape.weight_len()),
            ("grad_output", grad_output.len(), shape.output_len()),
        ],
    );
    let (h, w) = (shape.height, shape.width);
    let image_in = shape.channels * h * w;
    let image_out = shape.outputs * h * w;
    let mut grad_input = vec![0.0f32; shape.input_len()];
    if image_in == 0 || image_out == 0 {
        return ConvGrads { input: grad_input, weight: vec![0.0; shape.weight_len()], bias: vec![0.0; shape.outputs] };
    }
    let partials: Vec<(Vec<f32>, Vec<f32>)> = grad_input
        .par_chunks_mut(image_in)
        .zip(input.par_chunks(image_in))
        .zip(grad_output.par_chunks(image_out))
        .map(|((grad_image, image), grad)| {
            let padded = pad_image(&shape, image);
            let wide_grad = widen(&shape, grad);
            input_grad(&shape, weight, &wide_grad, grad_image);
            let weight_grad = weight_grad(&shape, &padded, &wide_grad);
            let bias_grad = grad.chunks_exact(h * w).map(|channel| channel.iter().sum()).collect();
            (weight_grad, bias_grad)
        })
        .collect();
    let mut weight_sum = vec![0.0f32; shape.weight_len()];
    let mut bias_sum = vec![0.0f32; shape.outputs];
    for (weight_grad, bias_grad) in &partials {
        weight_sum.iter_mut().zip(weight_grad).for_each(|(s, g)| *s += g);
        bias_sum.iter_mut().zip(bias_grad).for_each(|(s, g)| *s += g);
    }
    ConvGrads { input: grad_input, weight: weight_sum, bias: bias_sum }
}

/// One image's input gradient `[C, H, W]` from its widened output gradient.
fn input_grad(shape: &ConvShape, weight: &[f32], wide_grad: &[f32], out: &mut [f32]) {
    let (h, w, wp) = (shape.height, shape.width, shape.padded_width());
    let mut padded = vec![0.0f32; shape.padded_len()];
    for k in 0..9 {
        let dst = Strided { offset: shape.tap_offset(k), row_stride: shape.plane(), col_stride: 1 };
        // `W_kᵀ`: `[C, O]`, element `(c, o)` at `o·C·9 + c·9 + k`.
        let lhs = Strided { offset: k, row_stride: 9, col_stride: shape.channels * 9 };
        let dims = [shape.channels, shape.wide_pixels(), shape.outputs];
        product(shape, dims, &mut padded, dst, true, weight, lhs, wide_grad, wide(shape));
    }
    for (c, channel) in out.chunks_exact_mut(h * w).enumerate() {
        for (i, row) in channel.chunks_exact_mut(w).enumerate() {
            let start = c * shape.plane() + (i + 1) * wp + 1;
            row.copy_from_slice(&padded[start..start + w]);
        }
    }
}

/// One image's weight gradient `[O, C, 3, 3]`: `dW_k = dY · X_kᵀ` per tap.
fn weight_grad(shape: &ConvShape, padded: &[f32], wide_grad: &[f32]) -> Vec<f32> {
    let mut grad = vec![0.0f32; shape.weight_len()];
    for k in 0..9 {
        // `X_kᵀ`: `[H·Wp, C]`, element `(p, c)` at `c·plane + off_k + p`.
        let rhs = Strided { offset: shape.tap_offset(k), row_stride: 1, col_stride: shape.plane() };
        let dims = [shape.outputs, shape.channels, shape.wide_pixels()];
        product(shape, dims, &mut grad, tap_weights(shape, k), false, wide_grad, wide(shape), padded, rhs);
    }
    grad
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_keeps_every_gradient_value_but_the_negligible_ones() {
        let shape = ConvShape { images: 1, channels: 1, outputs: 2, height: 2, width: 3 };
        let tiny = f32::MIN_POSITIVE / 8.0;
        let grad = [1.0, -tiny, FLUSH_BELOW, -FLUSH_BELOW / 2.0, 1e-20, -3.0, 0.5, 2e-31, -1e-30, 0.0, 4.0, -0.25];
        assert!(tiny.is_subnormal(), "the test holds a subnormal value");
        let wide = widen(&shape, &grad);
        // Rows of width 3 padded to 5: two junk columns after each row.
        let expected = [
            [1.0, 0.0, FLUSH_BELOW, 0.0, 0.0],
            [0.0, 1e-20, -3.0, 0.0, 0.0],
            [0.5, 0.0, -1e-30, 0.0, 0.0],
            [0.0, 4.0, -0.25, 0.0, 0.0],
        ];
        assert_eq!(wide, expected.concat(), "values below 2^-100 are zero, the rest kept bit for bit");
    }
}
