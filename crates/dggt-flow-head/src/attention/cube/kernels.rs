//! The neighbourhood attention as CubeCL kernels: one cube of [`UNITS`] units per query, the arithmetic of the host
//! kernel ([`crate::attention::kernel`], whose table gives the buffers' shapes) spread over the cube's units
//! phase by phase, with the query's neighbourhood in shared memory between phases.
//!
//! Both passes start alike: every unit encodes some of the `k x hidden` (neighbour, channel) pairs into the shared
//! encodings `g`, then scores some of the `heads x k` (head, neighbour) pairs, then one unit per head turns its
//! scores into weights. The forward then has each unit sum some output channels over the neighbours. The
//! backward recomputes the same, then, phase by phase: the weights' gradients and the softmax's, the query's own
//! gradients (queries, turned queries), the encodings' pre-activation gradients (written over `g`), the offsets'
//! gradients, the query's share of the encoder's gradients (a `[4, hidden]` row per query, summed afterwards with
//! tensor operations: no contention on `4 hidden` addresses), and the target keys' and values' gradients, added
//! with [`FloatAdd`] (neighbours are shared between queries).
//!
//! Sizes (`k`, heads, width, hidden) are compile-time constants, one compiled kernel per head shape, so that loops
//! have fixed bounds and the barriers between phases sit in uniform control flow. A cube past the last query (the
//! grid is two-dimensional beyond 65 535 cubes) computes the last query's values and writes nothing.

use burn_cubecl::cubecl;
use cubecl::prelude::*;
use dggt_cube::atomic::FloatAdd;

use crate::attention::gelu::{A1, A2, A3, A4, A5, INV_SQRT_TAU, P};

/// Units per cube (one query).
pub const UNITS: usize = 64;

/// `1 / sqrt(2)`.
const FRAC_1_SQRT_2: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The head's sizes, compile-time constants of the kernels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Sizes {
    pub neighbours: usize,
    pub heads: usize,
    pub width: usize,
    pub hidden: usize,
}

/// The call's inputs (their shapes in the host kernel's table), one argument of both kernels.
#[derive(CubeLaunch, CubeType)]
pub struct Inputs {
    pub offsets: OwnedTensor<f32>,
    pub rows: OwnedTensor<i32>,
    pub keys_values: OwnedTensor<f32>,
    pub encoder_weight: OwnedTensor<f32>,
    pub encoder_bias: OwnedTensor<f32>,
    pub queries: OwnedTensor<f32>,
    pub turned: OwnedTensor<f32>,
}

/// A query's neighbourhood in shared memory: the encodings `g` `[k, hidden]` (in the backward, later their
/// pre-activation gradients) and the attention weights `[heads, k]`.
#[derive(CubeType)]
pub struct Neighbourhood {
    pub encoded: Shared<[f32]>,
    pub weights: Shared<[f32]>,
}

/// The cube's query, and whether it exists (a cube past the last query works on the last one, writing nothing).
#[cube]
fn cube_query(count: u32) -> (usize, bool) {
    let query = (CUBE_POS_Y * CUBE_COUNT_X + CUBE_POS_X) as usize;
    let count = count as usize;
    let valid = query < count;
    let mut clamped = query;
    if !valid {
        clamped = count - 1;
    }
    (clamped, valid)
}

/// `(Phi(z), phi(z))` as the host computes them (`gelu.rs`), with the device's `exp`.
#[cube]
fn normal(z: f32) -> (f32, f32) {
    let x = f32::abs(z) * FRAC_1_SQRT_2;
    let density = f32::exp(-x * x);
    let t = 1.0 / (1.0 + P * x);
    let polynomial = t * (A1 + t * (A2 + t * (A3 + t * (A4 + t * A5))));
    let tail = 0.5 * polynomial * density;
    let mut distribution = tail;
    if z >= 0.0 {
        distribution = 1.0 - tail;
    }
    (distribution, INV_SQRT_TAU * density)
}

/// The pre-activation of channel `c` of the encoding of offset `pair` (`query * k + j`).
#[cube]
fn pre_activation(inputs: &Inputs, pair: usize, c: usize, #[comptime] hidden: usize) -> f32 {
    let (offsets, weight) = (&inputs.offsets, &inputs.encoder_weight);
    let o = pair * 3;
    inputs.encoder_bias[c]
        + offsets[o] * weight[c]
        + offsets[o + 1] * weight[hidden + c]
        + offsets[o + 2] * weight[2 * hidden + c]
}

/// Softmax of `len` shared scores from `start`, in place (the maximum subtracted first).
#[cube]
fn softmax_row(scores: &mut Shared<[f32]>, start: usize, #[comptime] len: usize) {
    let mut max = scores[start];
    for j in 1..len {
        let s = scores[start + j];
        if s > max {
            max = s;
        }
    }
    let mut sum = 0.0f32;
    for j in 0..len {
        let e = f32::exp(scores[start + j] - max);
        scores[start + j] = e;
        sum += e;
    }
    for j in 0..len {
        scores[start + j] /= sum;
    }
}

/// The query's encodings and attention weights in shared memory (three phases, a barrier after each): how both
/// passes start.
#[cube]
fn query_neighbourhood(inputs: &Inputs, query: usize, #[comptime] sizes: Sizes) -> Neighbourhood {
    let (k, heads, width, hidden) = comptime!((sizes.neighbours, sizes.heads, sizes.width, sizes.hidden));
    let (rows, keys_values) = (&inputs.rows, &inputs.keys_values);
    let (queries, turned) = (&inputs.queries, &inputs.turned);
    let mut space = Neighbourhood {
        encoded: Shared::<[f32]>::new_slice(comptime!(k * hidden)),
        weights: Shared::<[f32]>::new_slice(comptime!(heads * k)),
    };
    let unit = UNIT_POS as usize;
    let pairs = comptime!(k * hidden);
    for round in 0..comptime!(pairs.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < pairs {
            let pre = pre_activation(inputs, query * k + t / hidden, t % hidden, hidden);
            let (distribution, _) = normal(pre);
            space.encoded[t] = pre * distribution;
        }
    }
    sync_cube();
    let scores = comptime!(heads * k);
    for round in 0..comptime!(scores.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < scores {
            let (h, j) = (t / k, t % k);
            let key = rows[query * k + j] as usize * comptime!(2 * heads * width) + h * width;
            let q = (query * heads + h) * width;
            let u = (query * heads + h) * hidden;
            let mut s = 0.0f32;
            for c in 0..width {
                s += queries[q + c] * keys_values[key + c];
            }
            for c in 0..hidden {
                s += turned[u + c] * space.encoded[j * hidden + c];
            }
            space.weights[t] = s;
        }
    }
    sync_cube();
    if unit < heads {
        softmax_row(&mut space.weights, unit * k, k);
    }
    sync_cube();
    space
}

/// The forward pass: `out [N, heads, width + hidden + 3]`, per head the weighted values, encodings and offsets.
#[cube(launch)]
pub fn attention_forward_kernel(inputs: &Inputs, out: &mut Tensor<f32>, count: u32, #[comptime] sizes: Sizes) {
    let (k, heads, width, hidden) = comptime!((sizes.neighbours, sizes.heads, sizes.width, sizes.hidden));
    let (query, valid) = cube_query(count);
    let space = query_neighbourhood(inputs, query, sizes);
    let (offsets, rows, keys_values) = (&inputs.offsets, &inputs.rows, &inputs.keys_values);
    let channels = comptime!(width + hidden + 3);
    let outputs = comptime!(heads * channels);
    let unit = UNIT_POS as usize;
    for round in 0..comptime!(outputs.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < outputs && valid {
            let (h, c) = (t / channels, t % channels);
            let mut sum = 0.0f32;
            for j in 0..k {
                let a = space.weights[h * k + j];
                let mut x = 0.0f32;
                if c < width {
                    let row = rows[query * k + j] as usize;
                    x = keys_values[row * comptime!(2 * heads * width) + comptime!(heads * width) + h * width + c];
                }
                if c >= width && c < width + hidden {
                    x = space.encoded[j * hidden + c - width];
                }
                if c >= width + hidden {
                    x = offsets[(query * k + j) * 3 + c - width - hidden];
                }
                sum += a * x;
            }
            out[query * outputs + t] = sum;
        }
    }
}

/// The backward pass from `grad_out` (shaped like the output): writes the query's own rows of `grad_offsets`,
/// `grad_queries`, `grad_turned`, its row `[4, hidden]` of `encoder_rows` (the encoder weight's three rows, then
/// the bias), and adds into `grad_keys_values` (zeroed by the caller).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn attention_backward_kernel<A: FloatAdd>(
    inputs: &Inputs,
    grad_out: &Tensor<f32>,
    grad_offsets: &mut Tensor<f32>,
    grad_queries: &mut Tensor<f32>,
    grad_turned: &mut Tensor<f32>,
    encoder_rows: &mut Tensor<f32>,
    grad_keys_values: &Tensor<Atomic<A::Slot>>,
    count: u32,
    #[comptime] sizes: Sizes,
) {
    let (k, heads, width, hidden) = comptime!((sizes.neighbours, sizes.heads, sizes.width, sizes.hidden));
    let (query, valid) = cube_query(count);
    let mut space = query_neighbourhood(inputs, query, sizes);
    let (offsets, rows, keys_values) = (&inputs.offsets, &inputs.rows, &inputs.keys_values);
    let (queries, turned, encoder_weight) = (&inputs.queries, &inputs.turned, &inputs.encoder_weight);
    // `[heads, k]`: the weights' gradients, then the scores'.
    let mut grads = Shared::<[f32]>::new_slice(comptime!(heads * k));
    let unit = UNIT_POS as usize;
    let channels = comptime!(width + hidden + 3);
    let kv_channels = comptime!(2 * heads * width);
    // The weights' gradients: da_hj = dvalues_h . value_j + dpooled_h . g_j + dmatched_h . o_j.
    let scores = comptime!(heads * k);
    for round in 0..comptime!(scores.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < scores {
            let (h, j) = (t / k, t % k);
            let g_out = (query * heads + h) * channels;
            let value = rows[query * k + j] as usize * kv_channels + comptime!(heads * width) + h * width;
            let mut d = 0.0f32;
            for c in 0..width {
                d += grad_out[g_out + c] * keys_values[value + c];
            }
            for c in 0..hidden {
                d += grad_out[g_out + width + c] * space.encoded[j * hidden + c];
            }
            for axis in 0..3usize {
                d += grad_out[g_out + width + hidden + axis] * offsets[(query * k + j) * 3 + axis];
            }
            grads[t] = d;
        }
    }
    sync_cube();
    // Through each head's softmax: ds_j = a_j (da_j - sum_i a_i da_i).
    if unit < heads {
        let start = unit * k;
        let mut mean = 0.0f32;
        for j in 0..k {
            mean += space.weights[start + j] * grads[start + j];
        }
        for j in 0..k {
            grads[start + j] = space.weights[start + j] * (grads[start + j] - mean);
        }
    }
    sync_cube();
    // The query's own: dq_h = sum_j ds_hj key_j, du_h = sum_j ds_hj g_j.
    let own = comptime!(heads * (width + hidden));
    for round in 0..comptime!(own.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < own && valid {
            let (h, c) = (t / (width + hidden), t % (width + hidden));
            let mut sum = 0.0f32;
            for j in 0..k {
                let ds = grads[h * k + j];
                if c < width {
                    sum += ds * keys_values[rows[query * k + j] as usize * kv_channels + h * width + c];
                } else {
                    sum += ds * space.encoded[j * hidden + c - width];
                }
            }
            if c < width {
                grad_queries[(query * heads + h) * width + c] = sum;
            } else {
                grad_turned[(query * heads + h) * hidden + c - width] = sum;
            }
        }
    }
    sync_cube();
    // The encodings' gradients, through the GELU: over `g` (no longer needed).
    let pairs = comptime!(k * hidden);
    for round in 0..comptime!(pairs.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < pairs {
            let (j, c) = (t / hidden, t % hidden);
            let mut grad = 0.0f32;
            for h in 0..heads {
                let u = turned[(query * heads + h) * hidden + c];
                let pooled = grad_out[(query * heads + h) * channels + width + c];
                grad += grads[h * k + j] * u + space.weights[h * k + j] * pooled;
            }
            let pre = pre_activation(inputs, query * k + j, c, hidden);
            let (distribution, density) = normal(pre);
            space.encoded[t] = grad * (distribution + pre * density);
        }
    }
    sync_cube();
    // The offsets': the matched offsets' share plus the encoder's.
    let axes = comptime!(k * 3);
    for round in 0..comptime!(axes.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < axes && valid {
            let (j, axis) = (t / 3, t % 3);
            let mut grad = 0.0f32;
            for h in 0..heads {
                grad += space.weights[h * k + j] * grad_out[(query * heads + h) * channels + width + hidden + axis];
            }
            for c in 0..hidden {
                grad += encoder_weight[axis * hidden + c] * space.encoded[j * hidden + c];
            }
            grad_offsets[query * axes + t] = grad;
        }
    }
    // The encoder's, this query's share: sum_j o_j,axis dpre_j (three rows) and sum_j dpre_j (the bias).
    for round in 0..comptime!(hidden.div_ceil(UNITS)) {
        let c = round * UNITS + unit;
        if c < hidden && valid {
            let mut along_x = 0.0f32;
            let mut along_y = 0.0f32;
            let mut along_z = 0.0f32;
            let mut bias = 0.0f32;
            for j in 0..k {
                let grad = space.encoded[j * hidden + c];
                let o = (query * k + j) * 3;
                along_x += offsets[o] * grad;
                along_y += offsets[o + 1] * grad;
                along_z += offsets[o + 2] * grad;
                bias += grad;
            }
            let row = query * comptime!(4 * hidden);
            encoder_rows[row + c] = along_x;
            encoder_rows[row + hidden + c] = along_y;
            encoder_rows[row + 2 * hidden + c] = along_z;
            encoder_rows[row + 3 * hidden + c] = bias;
        }
    }
    // The target keys' and values': dkey_j,h += ds_hj q_h, dvalue_j,h += a_hj dvalues_h.
    let shares = comptime!(k * heads * width);
    for round in 0..comptime!(shares.div_ceil(UNITS)) {
        let t = round * UNITS + unit;
        if t < shares && valid {
            let j = t / comptime!(heads * width);
            let (h, c) = ((t / width) % heads, t % width);
            let at = rows[query * k + j] as usize * kv_channels + h * width + c;
            let q = queries[(query * heads + h) * width + c];
            let grad_values = grad_out[(query * heads + h) * channels + c];
            A::add(grad_keys_values, at, grads[h * k + j] * q);
            A::add(grad_keys_values, at + comptime!(heads * width), space.weights[h * k + j] * grad_values);
        }
    }
}
