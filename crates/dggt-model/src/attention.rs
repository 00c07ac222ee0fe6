//! Multi-head self-attention with a fused qkv projection, optional per-head q/k LayerNorm (qk-norm) and
//! optional 2D RoPE, as the DINO, aggregator and camera-trunk blocks use it.
//!
//! Order: `qkv` -> split heads -> `q_norm`/`k_norm` over head_dim -> RoPE on q and k ->
//! `softmax(q k^T / sqrt(head_dim)) v` -> merge heads -> `proj`.
//!
//! Long sequences (the aggregator's global layers see every token of every frame) attend in blocks of queries
//! ([`attend`]): each block's softmax still runs over all keys, so the result is the same, but no call holds
//! more than [`MAX_SCORE_ELEMENTS`] scores, and the blocks' lengths are multiples of [`QUERY_ALIGN`], which the
//! GPU backends' flash-attention kernels need (an unaligned length, such as 930 tokens per frame, falls back to
//! the unfused computation and its full score matrix).

use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{Device, Tensor};

use crate::rope::RopeTable;

#[derive(Module, Debug)]
pub struct SelfAttention {
    pub qkv: Linear,
    pub q_norm: Option<LayerNorm>,
    pub k_norm: Option<LayerNorm>,
    pub proj: Linear,
    num_heads: usize,
}

impl SelfAttention {
    /// `qk_norm_eps`: `Some(eps)` adds the per-head LayerNorms on queries and keys.
    pub fn new(dim: usize, num_heads: usize, qk_norm_eps: Option<f64>, device: &Device) -> Self {
        let head_dim = dim / num_heads;
        let norm = |eps: f64| LayerNormConfig::new(head_dim).with_epsilon(eps).init(device);
        Self {
            qkv: LinearConfig::new(dim, 3 * dim).init(device),
            q_norm: qk_norm_eps.map(norm),
            k_norm: qk_norm_eps.map(norm),
            proj: LinearConfig::new(dim, dim).init(device),
            num_heads,
        }
    }

    /// `x`: `[batch, tokens, dim]`; `rope`, when given, must cover the `tokens` positions.
    pub fn forward(&self, x: Tensor<3>, rope: Option<&RopeTable>) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let h = self.num_heads;
        // [b, n, 3, h, d] -> [3, b, h, n, d]
        let qkv = self.qkv.forward(x).reshape([b, n, 3, h, c / h]).permute([2, 0, 3, 1, 4]);
        let head = |i: usize| qkv.clone().narrow(0, i, 1).squeeze_dim::<4>(0);
        let (mut q, mut k, v) = (head(0), head(1), head(2));
        if let Some(norm) = &self.q_norm {
            q = norm.forward(q);
        }
        if let Some(norm) = &self.k_norm {
            k = norm.forward(k);
        }
        if let Some(rope) = rope {
            q = rope.apply(q);
            k = rope.apply(k);
        }
        let out = attend(q, k, v);
        self.proj.forward(out.swap_dims(1, 2).reshape([b, n, c]))
    }
}

/// Most attention scores (`batch x heads x queries x keys`) one call may materialise: 1 GiB in f32. The GPU
/// backends cap one buffer at 4 GiB, and the unfused computation's score matrix of 12 frames at 518x350 (16
/// heads over 11 160 tokens) would be 8 GB.
pub const MAX_SCORE_ELEMENTS: usize = 1 << 28;

/// Query blocks are multiples of this many tokens (flash-attention kernels tile the queries).
pub const QUERY_ALIGN: usize = 128;

/// Most scores an aligned block of [`QUERY_ALIGN`] queries may hold when the budget allows fewer rows: 2 GiB in
/// f32, half a GPU buffer's limit. Past [`MAX_SCORE_ELEMENTS`], but an aligned block can run the flash kernel,
/// which holds no scores at all, where an unaligned one always materialises them (150 frames of 930 tokens, 16
/// heads: 120 rows fit the budget, 128 rows hold 1.1 GB of scores if materialised).
pub const MAX_ALIGNED_BLOCK_SCORES: usize = 1 << 29;

/// Sequences at most this long attend in one call (their scores are small, and one call is cheapest).
const SINGLE_CALL_TOKENS: usize = 1024;

/// `softmax(q k^T / sqrt(d)) v` for `q`, `k`, `v`: `[batch, heads, tokens, head_dim]`, in query blocks when
/// the sequence is long (see the module's doc).
pub fn attend(q: Tensor<4>, k: Tensor<4>, v: Tensor<4>) -> Tensor<4> {
    let [batch, heads, queries, _] = q.dims();
    let keys = k.dims()[2];
    let options = AttentionModuleOptions::default();
    let blocks = query_blocks(queries, batch * heads * keys);
    if blocks.len() == 1 {
        return attention(q, k, v, None, None, options);
    }
    let outputs = blocks
        .into_iter()
        .map(|block| {
            attention(q.clone().narrow(2, block.start, block.len()), k.clone(), v.clone(), None, None, options)
        })
        .collect();
    Tensor::cat(outputs, 2)
}

/// The query ranges one attention runs in, given the scores per query row (`batch x heads x keys`): one range
/// for a short sequence; otherwise aligned blocks within the score budget, then the unaligned remainder.
fn query_blocks(queries: usize, scores_per_query: usize) -> Vec<std::ops::Range<usize>> {
    if queries <= SINGLE_CALL_TOKENS && queries * scores_per_query <= MAX_SCORE_ELEMENTS {
        return std::iter::once(0..queries).collect();
    }
    let budget_rows = (MAX_SCORE_ELEMENTS / scores_per_query.max(1)).max(1);
    let block = if budget_rows >= QUERY_ALIGN {
        budget_rows / QUERY_ALIGN * QUERY_ALIGN
    } else if QUERY_ALIGN * scores_per_query <= MAX_ALIGNED_BLOCK_SCORES {
        QUERY_ALIGN
    } else {
        budget_rows
    };
    let aligned_end = if block % QUERY_ALIGN == 0 { queries / QUERY_ALIGN * QUERY_ALIGN } else { queries };
    let mut ranges: Vec<_> =
        (0..aligned_end).step_by(block).map(|start| start..(start + block).min(aligned_end)).collect();
    if aligned_end < queries {
        ranges.push(aligned_end..queries);
    }
    ranges
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Distribution, Tolerance};

    #[test]
    fn short_sequences_attend_in_one_call() {
        assert_eq!(query_blocks(232, 4 * 232), vec![0..232]);
    }

    #[test]
    fn long_sequences_attend_in_aligned_blocks_within_the_budget() {
        // 12 frames of 930 tokens, 16 heads: 8 GB of scores in one call.
        let queries = 11_160;
        let blocks = query_blocks(queries, 16 * queries);
        assert_eq!(blocks.first().unwrap().start, 0);
        assert_eq!(blocks.last().unwrap().end, queries);
        for pair in blocks.windows(2) {
            assert_eq!(pair[0].end, pair[1].start);
        }
        for block in &blocks[..blocks.len() - 1] {
            assert_eq!(block.start % QUERY_ALIGN, 0);
            assert!(block.len() % QUERY_ALIGN == 0 || block.end == queries / QUERY_ALIGN * QUERY_ALIGN);
            assert!(block.len() * 16 * queries <= MAX_SCORE_ELEMENTS, "{block:?}");
        }
        assert_eq!(blocks.last().unwrap(), &(queries / QUERY_ALIGN * QUERY_ALIGN..queries));
    }

    #[test]
    fn very_long_sequences_keep_aligned_blocks_while_one_fits_half_a_buffer() {
        // 150 frames of 930 tokens, 16 heads: the budget holds 120 query rows, an aligned block 1.1 GB of scores.
        let queries = 150 * 930;
        let blocks = query_blocks(queries, 16 * queries);
        let aligned = &blocks[..blocks.len() - 1];
        assert!(aligned.iter().all(|b| b.len() == QUERY_ALIGN && b.start % QUERY_ALIGN == 0), "{:?}", &blocks[..3]);
        assert_eq!(blocks.iter().map(|b| b.len()).sum::<usize>(), queries);
        // 600 frames: an aligned block would hold 4.6 GB; blocks shrink to the budget instead.
        let queries = 600 * 930;
        let blocks = query_blocks(queries, 16 * queries);
        assert!(blocks.iter().all(|b| b.len() * 16 * queries <= MAX_SCORE_ELEMENTS));
        assert_eq!(blocks.iter().map(|b| b.len()).sum::<usize>(), queries);
    }

    #[test]
    fn a_budget_below_one_aligned_block_still_covers_every_query() {
        let blocks = query_blocks(5000, MAX_SCORE_ELEMENTS / 50);
        assert!(blocks.iter().all(|b| b.len() <= 50));
        assert_eq!(blocks.iter().map(|b| b.len()).sum::<usize>(), 5000);
    }

    #[test]
    fn blocked_attention_equals_one_call() {
        let device = Device::default();
        let shape = [1, 2, 1100, 8];
        let [q, k, v] = [0, 1, 2].map(|_| Tensor::<4>::random(shape, Distribution::Normal(0.0, 1.0), &device));
        let one_call = attention(q.clone(), k.clone(), v.clone(), None, None, AttentionModuleOptions::default());
        let blocked = attend(q, k, v);
        blocked.into_data().assert_approx_eq::<f32>(&one_call.into_data(), Tolerance::absolute(1e-5));
    }
}
