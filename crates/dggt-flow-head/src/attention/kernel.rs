//! The neighbourhood attention of one query on the host, forward and backward, on flat `f32` buffers: what the
//! fused CPU op runs per query (in parallel over queries).
//!
//! Shapes (row-major), `N` queries of `k` neighbours, `heads` heads of `width` channels, `hidden` encoding
//! channels, `Nt` target points:
//!
//! | buffer | shape | |
//! |---|---|---|
//! | `offsets` | `[N, k, 3]` | neighbour offsets from the query, in spacing units |
//! | `rows` | `[N, k]` | the neighbours' rows of `keys_values` |
//! | `keys_values` | `[Nt, 2 hidden]` | per target point its feature key (`heads x width`), then its value |
//! | `encoder_weight` | `[3, hidden]` | the offset encoding's first layer (input-major, as burn stores it) |
//! | `encoder_bias` | `[hidden]` | |
//! | `queries` | `[N, heads, width]` | each head's query, already divided by `sqrt(width)` |
//! | `turned` | `[N, heads, hidden]` | each head's query turned through the folded key matrix, likewise scaled |
//! | output | `[N, heads, width + hidden + 3]` | per head: attended values, pooled encodings, matched offset |
//!
//! Per neighbour `j`: `g_j = GELU(o_j W + b)`; per head `s_j = q . key_j + u . g_j`, `a = softmax_j(s)`; out:
//! `sum a_j value_j`, `sum a_j g_j`, `sum a_j o_j`. The backward recomputes `g` and `a` from the inputs rather than
//! keeping `[N, k, hidden]` tensors. `hidden` here is the encoding's width, equal to `heads x width` in the head.

use crate::attention::gelu::{gelu, gelu_and_slope};

/// Sizes of one call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    pub queries: usize,
    pub neighbours: usize,
    pub heads: usize,
    pub width: usize,
    pub hidden: usize,
    pub targets: usize,
}

impl Dims {
    /// Channels of one head's output row: values, pooled encodings, matched offset.
    pub fn out_channels(&self) -> usize {
        self.width + self.hidden + 3
    }

    /// Channels of one row of `keys_values`.
    pub fn key_value_channels(&self) -> usize {
        2 * self.heads * self.width
    }
}

/// The inputs of one call (see the module's table).
#[derive(Debug, Clone, Copy)]
pub struct HostInputs<'a> {
    pub dims: Dims,
    pub offsets: &'a [f32],
    pub rows: &'a [usize],
    pub keys_values: &'a [f32],
    pub encoder_weight: &'a [f32],
    pub encoder_bias: &'a [f32],
    pub queries: &'a [f32],
    pub turned: &'a [f32],
}

/// Gradients of the differentiable inputs, shaped like them.
#[derive(Debug, Clone, PartialEq)]
pub struct HostGrads {
    pub offsets: Vec<f32>,
    pub keys_values: Vec<f32>,
    pub encoder_weight: Vec<f32>,
    pub encoder_bias: Vec<f32>,
    pub queries: Vec<f32>,
    pub turned: Vec<f32>,
}

/// Per-query working memory: the encodings' pre-activations and activations `[k, hidden]`, the attention weights
/// `[heads, k]`; for the backward, the gradients of the encodings `[k, hidden]` and of one head's scores `[k]`.
#[derive(Debug, Clone)]
pub struct Scratch {
    pre: Vec<f32>,
    encoded: Vec<f32>,
    weights: Vec<f32>,
    grad_encoded: Vec<f32>,
    grad_scores: Vec<f32>,
}

impl Scratch {
    pub fn new(dims: &Dims) -> Self {
        Self {
            pre: vec![0.0; dims.neighbours * dims.hidden],
            encoded: vec![0.0; dims.neighbours * dims.hidden],
            weights: vec![0.0; dims.heads * dims.neighbours],
            grad_encoded: vec![0.0; dims.neighbours * dims.hidden],
            grad_scores: vec![0.0; dims.neighbours],
        }
    }
}

impl HostInputs<'_> {
    fn offset(&self, query: usize, j: usize) -> &[f32] {
        let at = (query * self.dims.neighbours + j) * 3;
        &self.offsets[at..at + 3]
    }

    /// Neighbour `j`'s key or value block of head `head`.
    fn key_value(&self, query: usize, j: usize, head: usize, part: Part) -> &[f32] {
        let Dims { neighbours, heads, width, .. } = self.dims;
        let row = self.rows[query * neighbours + j];
        let at = row * self.dims.key_value_channels() + part.block() * heads * width + head * width;
        &self.keys_values[at..at + width]
    }

    fn query(&self, query: usize, head: usize) -> &[f32] {
        let width = self.dims.width;
        let at = (query * self.dims.heads + head) * width;
        &self.queries[at..at + width]
    }

    fn turned(&self, query: usize, head: usize) -> &[f32] {
        let hidden = self.dims.hidden;
        let at = (query * self.dims.heads + head) * hidden;
        &self.turned[at..at + hidden]
    }

    /// The encodings of the query's neighbours into `scratch` (`pre` always; `encoded` as GELU of it).
    fn encode(&self, query: usize, scratch: &mut Scratch) {
        let hidden = self.dims.hidden;
        let (w0, rest) = self.encoder_weight.split_at(hidden);
        let (w1, w2) = rest.split_at(hidden);
        let rows = scratch.pre.chunks_exact_mut(hidden).zip(scratch.encoded.chunks_exact_mut(hidden));
        for (j, (pre, encoded)) in rows.enumerate() {
            let o = self.offset(query, j);
            // Zipped rather than indexed, so that the loop has no bounds checks and vectorises.
            let weights = w0.iter().zip(w1).zip(w2).zip(self.encoder_bias);
            for ((pre, encoded), (((a, b), c), bias)) in pre.iter_mut().zip(encoded.iter_mut()).zip(weights) {
                *pre = bias + o[0] * a + o[1] * b + o[2] * c;
                *encoded = gelu(*pre);
            }
        }
    }

    /// The attention weights of every head over the query's neighbours into `scratch.weights` (needs `encode`).
    fn attention_weights(&self, query: usize, scratch: &mut Scratch) {
        let Dims { neighbours: k, heads, hidden, .. } = self.dims;
        for head in 0..heads {
            let (q, u) = (self.query(query, head), self.turned(query, head));
            let weights = &mut scratch.weights[head * k..(head + 1) * k];
            for (j, weight) in weights.iter_mut().enumerate() {
                let g = &scratch.encoded[j * hidden..(j + 1) * hidden];
                *weight = dot(q, self.key_value(query, j, head, Part::Key)) + dot(u, g);
            }
            softmax(weights);
        }
    }
}

/// Which half of a `keys_values` row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    Key,
    Value,
}

impl Part {
    fn block(self) -> usize {
        match self {
            Self::Key => 0,
            Self::Value => 1,
        }
    }
}

/// The output row `[heads, width + hidden + 3]` of `query`.
pub fn forward_query(inputs: &HostInputs, query: usize, scratch: &mut Scratch, out: &mut [f32]) {
    let Dims { neighbours: k, heads, width, hidden, .. } = inputs.dims;
    inputs.encode(query, scratch);
    inputs.attention_weights(query, scratch);
    out.fill(0.0);
    for (head, row) in out.chunks_exact_mut(inputs.dims.out_channels()).enumerate().take(heads) {
        let (values, rest) = row.split_at_mut(width);
        let (pooled, matched) = rest.split_at_mut(hidden);
        for j in 0..k {
            let a = scratch.weights[head * k + j];
            axpy(a, inputs.key_value(query, j, head, Part::Value), values);
            axpy(a, &scratch.encoded[j * hidden..(j + 1) * hidden], pooled);
            axpy(a, inputs.offset(query, j), matched);
        }
    }
}

/// Gradients one query contributes, given its output row's gradient `grad_out`: its own rows of the offsets,
/// queries and turned queries are written; the shared tensors' gradients (`keys_values`, the encoder's weight
/// and bias) are added to `shared`.
pub fn backward_query(
    inputs: &HostInputs,
    query: usize,
    grad_out: &[f32],
    scratch: &mut Scratch,
    own: OwnGrads,
    shared: &mut SharedGrads,
) {
    let Dims { neighbours: k, heads, width, hidden, .. } = inputs.dims;
    inputs.encode(query, scratch);
    inputs.attention_weights(query, scratch);
    let OwnGrads { offsets: grad_offsets, queries: grad_queries, turned: grad_turned } = own;
    grad_offsets.fill(0.0);
    let mut grad_encoded = std::mem::take(&mut scratch.grad_encoded);
    let mut grad_scores = std::mem::take(&mut scratch.grad_scores);
    grad_encoded.fill(0.0);
    for head in 0..heads {
        let row = &grad_out[head * inputs.dims.out_channels()..(head + 1) * inputs.dims.out_channels()];
        let (grad_values, rest) = row.split_at(width);
        let (grad_pooled, grad_matched) = rest.split_at(hidden);
        let weights = &scratch.weights[head * k..(head + 1) * k];
        for (j, grad_score) in grad_scores.iter_mut().enumerate() {
            let g = &scratch.encoded[j * hidden..(j + 1) * hidden];
            *grad_score = dot(grad_values, inputs.key_value(query, j, head, Part::Value))
                + dot(grad_pooled, g)
                + dot(grad_matched, inputs.offset(query, j));
        }
        // Through the softmax: ds_j = a_j (da_j - sum_i a_i da_i).
        let mean = dot(weights, &grad_scores);
        grad_scores.iter_mut().zip(weights).for_each(|(d, a)| *d = a * (*d - mean));
        let (q, u) = (inputs.query(query, head), inputs.turned(query, head));
        let grad_q = &mut grad_queries[head * width..(head + 1) * width];
        let grad_u = &mut grad_turned[head * hidden..(head + 1) * hidden];
        grad_q.fill(0.0);
        grad_u.fill(0.0);
        for j in 0..k {
            let (ds, a) = (grad_scores[j], weights[j]);
            axpy(ds, inputs.key_value(query, j, head, Part::Key), grad_q);
            axpy(ds, &scratch.encoded[j * hidden..(j + 1) * hidden], grad_u);
            let grad_g = &mut grad_encoded[j * hidden..(j + 1) * hidden];
            axpy(ds, u, grad_g);
            axpy(a, grad_pooled, grad_g);
            axpy(a, grad_matched, &mut grad_offsets[j * 3..j * 3 + 3]);
            shared.add_key_value(inputs, query, j, head, Part::Key, ds, q);
            shared.add_key_value(inputs, query, j, head, Part::Value, a, grad_values);
        }
    }
    shared.add_encoder(inputs, query, scratch, &mut grad_encoded, grad_offsets);
    (scratch.grad_encoded, scratch.grad_scores) = (grad_encoded, grad_scores);
}

/// The rows of one query's gradients that belong to it alone.
pub struct OwnGrads<'a> {
    /// `[k, 3]`.
    pub offsets: &'a mut [f32],
    /// `[heads, width]`.
    pub queries: &'a mut [f32],
    /// `[heads, hidden]`.
    pub turned: &'a mut [f32],
}

/// Gradients every query adds to: one set per worker, summed at the end.
#[derive(Debug, Clone, PartialEq)]
pub struct SharedGrads {
    pub keys_values: Vec<f32>,
    pub encoder_weight: Vec<f32>,
    pub encoder_bias: Vec<f32>,
}

impl SharedGrads {
    pub fn zeros(dims: &Dims) -> Self {
        Self {
            keys_values: vec![0.0; dims.targets * dims.key_value_channels()],
            encoder_weight: vec![0.0; 3 * dims.hidden],
            encoder_bias: vec![0.0; dims.hidden],
        }
    }

    /// The sum of two workers' gradients.
    // The shape of rayon's `reduce` operator, which hands both sides over by value.
    #[allow(clippy::needless_pass_by_value)]
    pub fn sum(mut self, other: Self) -> Self {
        for (into, from) in [
            (&mut self.keys_values, &other.keys_values),
            (&mut self.encoder_weight, &other.encoder_weight),
            (&mut self.encoder_bias, &other.encoder_bias),
        ] {
            into.iter_mut().zip(from).for_each(|(a, b)| *a += b);
        }
        self
    }

    #[allow(clippy::too_many_arguments)]
    fn add_key_value(
        &mut self,
        inputs: &HostInputs,
        query: usize,
        j: usize,
        head: usize,
        part: Part,
        scale: f32,
        x: &[f32],
    ) {
        let Dims { neighbours, heads, width, .. } = inputs.dims;
        let row = inputs.rows[query * neighbours + j];
        let at = row * inputs.dims.key_value_channels() + part.block() * heads * width + head * width;
        axpy(scale, x, &mut self.keys_values[at..at + width]);
    }

    /// Through the GELU and the encoder's first layer: the encoder's gradients, and the offsets' share.
    fn add_encoder(
        &mut self,
        inputs: &HostInputs,
        query: usize,
        scratch: &Scratch,
        grad_encoded: &mut [f32],
        grad_offsets: &mut [f32],
    ) {
        let hidden = inputs.dims.hidden;
        let w = inputs.encoder_weight;
        for j in 0..inputs.dims.neighbours {
            let o = inputs.offset(query, j);
            let grad_pre = &mut grad_encoded[j * hidden..(j + 1) * hidden];
            for (c, grad) in grad_pre.iter_mut().enumerate() {
                *grad *= gelu_and_slope(scratch.pre[j * hidden + c]).1;
            }
            for axis in 0..3 {
                grad_offsets[j * 3 + axis] += dot(&w[axis * hidden..(axis + 1) * hidden], grad_pre);
                axpy(o[axis], grad_pre, &mut self.encoder_weight[axis * hidden..(axis + 1) * hidden]);
            }
            axpy(1.0, grad_pre, &mut self.encoder_bias);
        }
    }
}

/// The dot product, summed in eight lanes so that it vectorises.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 8;
    let mut lanes = [0.0f32; LANES];
    let (a_chunks, b_chunks) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = a_chunks.remainder().iter().zip(b_chunks.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in a_chunks.zip(b_chunks) {
        for lane in 0..LANES {
            lanes[lane] += x[lane] * y[lane];
        }
    }
    lanes.iter().sum::<f32>() + tail
}

/// `y += a x`.
fn axpy(a: f32, x: &[f32], y: &mut [f32]) {
    y.iter_mut().zip(x).for_each(|(y, x)| *y += a * x);
}

/// In place, with the maximum subtracted first (a non-finite score makes the row `NaN`, as it would in a tensor
/// softmax).
fn softmax(scores: &mut [f32]) {
    let max = scores.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for s in scores.iter_mut() {
        *s = (*s - max).exp();
        sum += *s;
    }
    scores.iter_mut().for_each(|s| *s /= sum);
}
