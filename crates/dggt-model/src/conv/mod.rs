//! The DPT heads' convolutions as matrix products, forward and backward, instead of burn's own convolutions: on
//! the CPU backend, burn's im2col convolution (whose weight gradient is a convolution by the whole output gradient
//! and whose input gradient is a transposed convolution); on GPU devices, its direct convolution kernel (what a
//! build without autotune runs, and autotune's only candidate for a 3x3 convolution without the matrix units),
//! which took two thirds of a forward pass on an H200 against the matrix products' kernels. Same values up to the
//! order of the sums.
//!
//! - [`conv2d`]: a 3x3 convolution with stride 1 and zero padding 1 runs, for `f32` on the `Flex` CPU device, the
//!   host kernels of [`host`] (nine shifted matrix products; a backend extension with a hand-written backward,
//!   [`op`]); elsewhere a 3x3 convolution with zero padding 1 and any square stride (the DPT's stride-2
//!   downsampling too) is three matrix products, one per kernel row, over the channels of three shifted copies of
//!   the input (burn's autodiff differentiates them); a 1x1 convolution with stride 1 and no padding is one matrix
//!   product over the channels on every device.
//! - [`conv_transpose2d`]: a transposed convolution whose stride equals its kernel (no padding), the DPT's x2
//!   and x4 resize, writes disjoint `k x k` patches: one matrix product and a reshuffle of the patches (`f32` on
//!   the `Flex` device; elsewhere the module's own forward).
//!
//! Other settings run the module's own forward.

mod host;
mod op;

use burn::backend::Dispatch;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::tensor::Slice;
use burn::tensor::ops::PadMode;
use burn::tensor::{DType, Device, Tensor};

use op::Conv3x3Ops;

/// `conv.forward(x)` for `x` `[N, C, H, W]`, as matrix products where they apply.
pub fn conv2d(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    match Conv2dRoute::of(conv, &x) {
        Conv2dRoute::SameThreeByThree => same_3x3(conv, x),
        Conv2dRoute::ShiftedRows => shifted_rows_3x3(conv, x),
        Conv2dRoute::Pointwise => pointwise(conv, x),
        Conv2dRoute::Module => conv.forward(x),
    }
}

/// `conv.forward(x)` for `x` `[N, C, h, w]`, as a matrix product where the patches are disjoint.
pub fn conv_transpose2d(conv: &ConvTranspose2d, x: Tensor<4>) -> Tensor<4> {
    let disjoint = conv.stride == conv.kernel_size
        && conv.padding == [0, 0]
        && conv.padding_out == [0, 0]
        && conv.dilation == [1, 1]
        && conv.groups == 1;
    if !(disjoint && host_f32(&x, conv.weight.val().dtype())) {
        return conv.forward(x);
    }
    let [n, c, h, w] = x.dims();
    let [_, o, kh, kw] = conv.weight.dims();
    // y[n, o, i·kh + p, j·kw + q] = Σ_c x[n, c, i, j] · W[c, o, p, q] + b[o].
    let weight = conv.weight.val().reshape([1, c, o * kh * kw]).swap_dims(1, 2);
    let patches = weight.matmul(x.reshape([n, c, h * w]));
    let y = patches.reshape([n, o, kh, kw, h, w]).permute([0, 1, 4, 2, 5, 3]).reshape([n, o, h * kh, w * kw]);
    add_bias(y, conv.bias.as_ref().map(|b| b.val()))
}

/// Which computation [`conv2d`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Conv2dRoute {
    /// The host kernels of a 3x3 convolution with zero padding 1 (`f32` on the `Flex` device).
    SameThreeByThree,
    /// A 3x3 convolution with zero padding 1 on any other device or precision: a matrix product per kernel row.
    ShiftedRows,
    /// One matrix product over the channels.
    Pointwise,
    /// The module's own forward.
    Module,
}

impl Conv2dRoute {
    fn of(conv: &Conv2d, x: &Tensor<4>) -> Self {
        let [stride_y, stride_x] = conv.stride;
        if !(stride_y == stride_x && conv.dilation == [1, 1] && conv.groups == 1) {
            return Self::Module;
        }
        let unit_stride = stride_y == 1;
        match (conv.kernel_size, &conv.padding) {
            ([3, 3], PaddingConfig2d::Explicit(1, 1, 1, 1))
                if !host_f32(x, conv.weight.val().dtype()) && x.shape().num_elements() > 0 =>
            {
                Self::ShiftedRows
            }
            ([3, 3], PaddingConfig2d::Explicit(1, 1, 1, 1)) if unit_stride => Self::SameThreeByThree,
            ([1, 1], PaddingConfig2d::Valid | PaddingConfig2d::Explicit(0, 0, 0, 0)) if unit_stride => Self::Pointwise,
            _ => Self::Module,
        }
    }
}

fn same_3x3(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let weight = conv.weight.val();
    let bias = match &conv.bias {
        Some(bias) => bias.val(),
        None => Tensor::zeros([weight.dims()[0]], &x.device()),
    };
    let output =
        <Dispatch as Conv3x3Ops>::conv3x3_same(x.into_dispatch(), weight.into_dispatch(), bias.into_dispatch());
    Tensor::from_dispatch(output)
}

/// `y = Σ_r W[:, :, r, :] · [x shifted by (r - 1, -1), (r - 1, 0), (r - 1, 1)]`, taken every `s`-th row and column
/// for a stride `s`: per kernel row `r`, the input's three horizontal shifts (zero padded) stacked along the
/// channels `[N, 3C, H'·W']` (shift-major, the weight's column order after its permute), one matrix product with
/// the row's weights `[O, 3C]`. Three times the output's input footprint at a time instead of im2col's nine.
fn shifted_rows_3x3(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let o = conv.weight.dims()[0];
    let stride = conv.stride[0];
    let (out_h, out_w) = ((h - 1) / stride + 1, (w - 1) / stride + 1);
    let padded = x.pad([(1, 1), (1, 1)], PadMode::Constant(0.0));
    // Every `stride`-th of `count` entries from `first`.
    let taken = |first: usize, count: usize| {
        Slice::new(first as isize, Some((first + stride * (count - 1) + 1) as isize), stride as isize)
    };
    // [O, C, kh, kw] -> [kh, O, kw, C]: row r's weights as [O, 3C], shift-major.
    let weight = conv.weight.val().permute([2, 0, 3, 1]);
    let mut y: Option<Tensor<3>> = None;
    for row in 0..3 {
        let shifts: Vec<Tensor<4>> = (0..3)
            .map(|column| {
                let whole = Slice::new(0, None, 1);
                padded.clone().slice([whole, whole, taken(row, out_h), taken(column, out_w)])
            })
            .collect();
        let columns = Tensor::cat(shifts, 1).reshape([n, 3 * c, out_h * out_w]);
        let row_weight = weight.clone().slice([row..row + 1, 0..o, 0..3, 0..c]).reshape([1, o, 3 * c]);
        let product = row_weight.matmul(columns);
        y = Some(match y {
            Some(sum) => sum + product,
            None => product,
        });
    }
    let y = y.expect("three kernel rows").reshape([n, o, out_h, out_w]);
    add_bias(y, conv.bias.as_ref().map(|b| b.val()))
}

fn pointwise(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let o = conv.weight.dims()[0];
    let weight = conv.weight.val().reshape([1, o, c]);
    let y = weight.matmul(x.reshape([n, c, h * w])).reshape([n, o, h, w]);
    add_bias(y, conv.bias.as_ref().map(|b| b.val()))
}

fn add_bias(y: Tensor<4>, bias: Option<Tensor<1>>) -> Tensor<4> {
    match bias {
        Some(bias) => {
            let o = bias.dims()[0];
            y + bias.reshape([1, o, 1, 1])
        }
        None => y,
    }
}

/// Whether `x` and weights of `weight_dtype` are `f32` on the `Flex` CPU device (directly or under autodiff).
fn host_f32(x: &Tensor<4>, weight_dtype: DType) -> bool {
    x.dtype() == DType::F32 && weight_dtype == DType::F32 && on_flex(&x.device())
}

fn on_flex(device: &Device) -> bool {
    device.clone().without_autodiff() == Device::flex()
}

#[cfg(test)]
mod tests {
    use burn::nn::conv::{Conv2dConfig, ConvTranspose2dConfig};
    use burn::tensor::TensorData;

    use super::*;

    fn input(shape: [usize; 4], seed: usize, device: &Device) -> Tensor<4> {
        let values = (0..shape.iter().product()).map(|i| (((i + seed) * 7919) % 1009) as f32 / 1009.0 - 0.5).collect();
        Tensor::<4>::from_data(TensorData::new(values, shape), device).require_grad()
    }

    /// Output, input gradient, weight gradient and bias gradient of `layer` under a random linear loss.
    fn outputs_and_grads(
        layer: impl Fn(Tensor<4>) -> Tensor<4>,
        x: &Tensor<4>,
        weight: &Tensor<4>,
        bias: Option<&Tensor<1>>,
    ) -> Vec<Vec<f32>> {
        let y = layer(x.clone());
        // A fixed, varied loss weight per output value: the same on both sides of a comparison.
        let count = y.shape().num_elements() as i64;
        let loss_weights = Tensor::arange(0..count, &y.device()).float().mul_scalar(0.37).sin().reshape(y.dims());
        let grads = (y.clone() * loss_weights).sum().backward();
        let flat = |t: Tensor<4>| t.into_data().try_to_vec::<f32>().unwrap();
        let mut all = vec![flat(y), flat(x.grad(&grads).expect("an input gradient"))];
        all.push(flat(weight.grad(&grads).expect("a weight gradient")));
        if let Some(bias) = bias {
            all.push(bias.grad(&grads).expect("a bias gradient").into_data().try_to_vec::<f32>().unwrap());
        }
        all
    }

    fn assert_close(case: &str, ours: &[Vec<f32>], reference: &[Vec<f32>]) {
        let names = ["output", "input gradient", "weight gradient", "bias gradient"];
        assert_eq!(ours.len(), reference.len(), "{case}: gradient count");
        for ((a, b), what) in ours.iter().zip(reference).zip(names) {
            assert_eq!(a.len(), b.len(), "{case}: {what} sizes");
            let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let worst = a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-5 * scale, "{case}: {what} differs by {worst} (scale {scale})");
        }
    }

    /// Asserts that `ours` computes what `module` (burn's own forward) does at `x`, in value and gradients.
    fn assert_matches_module(
        case: &str,
        ours: impl Fn(Tensor<4>) -> Tensor<4>,
        module: impl Fn(Tensor<4>) -> Tensor<4>,
        x: &Tensor<4>,
        (weight, bias): (Tensor<4>, Option<Tensor<1>>),
    ) {
        let ours = outputs_and_grads(ours, x, &weight, bias.as_ref());
        let reference = outputs_and_grads(module, x, &weight, bias.as_ref());
        assert_close(case, &ours, &reference);
    }

    fn parameters_of(conv: &Conv2d) -> (Tensor<4>, Option<Tensor<1>>) {
        (conv.weight.val(), conv.bias.as_ref().map(|b| b.val()))
    }

    #[test]
    fn convolutions_as_products_match_burns_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        // The DPT heads' shapes at training sizes, single pixels and rows, one input channel.
        let cases = [
            ([4, 16, 14, 21], 32, 3, true),
            ([3, 32, 8, 12], 16, 3, false),
            ([2, 3, 1, 1], 5, 3, true),
            ([1, 1, 1, 9], 2, 3, true),
            ([2, 5, 7, 1], 3, 3, true),
            ([3, 16, 14, 21], 7, 1, true),
            ([2, 4, 1, 3], 2, 1, false),
        ];
        for (seed, (shape, outputs, kernel, bias)) in cases.into_iter().enumerate() {
            let padding = if kernel == 3 { PaddingConfig2d::Explicit(1, 1, 1, 1) } else { PaddingConfig2d::Valid };
            let conv = Conv2dConfig::new([shape[1], outputs], [kernel, kernel])
                .with_padding(padding)
                .with_bias(bias)
                .init(&device);
            let x = input(shape, seed, &device);
            let expected = if kernel == 3 { Conv2dRoute::SameThreeByThree } else { Conv2dRoute::Pointwise };
            assert_eq!(Conv2dRoute::of(&conv, &x), expected, "{shape:?}");
            let case = format!("{kernel}x{kernel} {shape:?} -> {outputs}");
            assert_matches_module(&case, |x| conv2d(&conv, x), |x| conv.forward(x), &x, parameters_of(&conv));
            if kernel == 3 {
                // The route of the other devices, on this one.
                let case = format!("shifted rows {shape:?} -> {outputs}");
                let rows = |x| shifted_rows_3x3(&conv, x);
                assert_matches_module(&case, rows, |x| conv.forward(x), &x, parameters_of(&conv));
            }
        }
    }

    #[test]
    fn disjoint_transposed_convolutions_match_burns_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        for (seed, (shape, outputs, k)) in
            [([3, 16, 4, 6], 16, 4), ([2, 8, 3, 5], 4, 2), ([1, 2, 1, 1], 3, 2)].into_iter().enumerate()
        {
            let conv = ConvTranspose2dConfig::new([shape[1], outputs], [k, k]).with_stride([k, k]).init(&device);
            let x = input(shape, seed, &device);
            let parameters = (conv.weight.val(), conv.bias.as_ref().map(|b| b.val()));
            let case = format!("transposed x{k} {shape:?} -> {outputs}");
            assert_matches_module(&case, |x| conv_transpose2d(&conv, x), |x| conv.forward(x), &x, parameters);
        }
    }

    #[test]
    fn strided_shifted_rows_match_burns_convolution_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        // The DPT's stride-2 downsampling (even and odd sizes), a single pixel, stride 3.
        for (seed, (shape, outputs, stride)) in
            [([2, 8, 9, 12], 6, 2), ([1, 4, 8, 5], 3, 2), ([1, 3, 1, 1], 2, 2), ([2, 5, 10, 7], 4, 3)]
                .into_iter()
                .enumerate()
        {
            let conv = Conv2dConfig::new([shape[1], outputs], [3, 3])
                .with_stride([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(&device);
            let x = input(shape, seed, &device);
            let case = format!("stride {stride} {shape:?} -> {outputs}");
            assert_matches_module(&case, |x| shifted_rows_3x3(&conv, x), |x| conv.forward(x), &x, parameters_of(&conv));
        }
    }

    #[test]
    fn other_convolutions_keep_the_modules_forward_and_other_precisions_take_the_shifted_rows() {
        let device = Device::flex();
        let padded = PaddingConfig2d::Explicit(1, 1, 1, 1);
        let strided = Conv2dConfig::new([3, 4], [3, 3]).with_stride([2, 2]).with_padding(padded.clone()).init(&device);
        let unpadded = Conv2dConfig::new([3, 4], [3, 3]).init(&device);
        let same = Conv2dConfig::new([3, 4], [3, 3]).with_padding(padded).init(&device);
        let x = Tensor::<4>::zeros([1, 3, 8, 8], &device);
        assert_eq!(Conv2dRoute::of(&strided, &x), Conv2dRoute::Module);
        assert_eq!(Conv2dRoute::of(&strided, &x.clone().cast(DType::F16)), Conv2dRoute::ShiftedRows);
        let empty = Tensor::<4>::zeros([1, 3, 0, 8], &device).cast(DType::F16);
        assert_eq!(Conv2dRoute::of(&strided, &empty), Conv2dRoute::Module, "an empty map keeps burn's forward");
        assert_eq!(Conv2dRoute::of(&unpadded, &x), Conv2dRoute::Module);
        assert_eq!(Conv2dRoute::of(&same, &x.clone().cast(DType::F16)), Conv2dRoute::ShiftedRows);
        assert_eq!(Conv2dRoute::of(&same, &x), Conv2dRoute::SameThreeByThree);
    }
}
