//! The attention's sums with burn's tensor operations and autodiff: the neighbours' keys and values gathered
//! `[N, k, 2 hidden]`, their encodings computed as tensors `[N, k, hidden]`, the sums as batched products.

use burn::tensor::Tensor;
use burn::tensor::activation::{gelu, softmax};

use super::{AttendedTensors, AttentionTensors};

pub fn attend(inputs: AttentionTensors) -> AttendedTensors {
    let AttentionTensors { offsets, rows, keys_values, encoder_weight, encoder_bias, queries, turned } = inputs;
    let [n, k, _] = offsets.dims();
    let [_, heads, width] = queries.dims();
    let [_, _, hidden] = turned.dims();
    let channels = keys_values.dims()[1];
    let gathered = keys_values.select(0, rows.reshape([n * k])).reshape([n, k, channels]);
    let by_head = |t: Tensor<3>| t.reshape([n, k, heads, width]).swap_dims(1, 2);
    let keys = by_head(gathered.clone().narrow(2, 0, heads * width));
    let values = by_head(gathered.narrow(2, heads * width, heads * width));
    let encoded = offsets.clone().reshape([n * k, 3]).matmul(encoder_weight) + encoder_bias.reshape([1, hidden]);
    let encoded = gelu(encoded).reshape([n, k, hidden]);
    // [N, heads, k]: the features' scores plus the encodings' scores.
    let feature_scores = queries.unsqueeze_dim::<4>(2).matmul(keys.swap_dims(2, 3)).reshape([n, heads, k]);
    let offset_scores = turned.matmul(encoded.clone().swap_dims(1, 2));
    let weights = softmax(feature_scores + offset_scores, 2);
    AttendedTensors {
        values: weights.clone().unsqueeze_dim::<4>(2).matmul(values).reshape([n, heads, width]),
        pooled: weights.clone().matmul(encoded),
        matched: weights.matmul(offsets),
    }
}
