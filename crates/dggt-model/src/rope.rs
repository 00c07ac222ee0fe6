//! 2D rotary position embedding of the aggregator's attention (VGGT's RoPE2D).
//!
//! Each token has a position `(y, x)`: `(row + 1, col + 1)` for patches and `(0, 0)` for the camera and
//! register tokens. The head dimension is split in half; the first half is rotated by `y`, the second by `x`.
//! Within each half of width `d` the rotation is the rotate-half form: angles `pos * inv_freq` with
//! `inv_freq[k] = base^(-2k / d)` for `k < d / 2`, duplicated to `[a, a]`, and
//! `out = v * cos + rotate_half(v) * sin`, `rotate_half([v1, v2]) = [-v2, v1]`.
//! The cos/sin tables are computed on the host once per token layout.

use burn::tensor::Tensor;

use crate::constant::ConstantSite;

/// cos/sin tables for a fixed token sequence, each `[tokens, head_dim]`.
#[derive(Debug, Clone)]
pub struct RopeTable {
    cos: Tensor<2>,
    sin: Tensor<2>,
}

impl RopeTable {
    /// Tables for one frame's tokens: `special_tokens` at `(0, 0)`, then a `rows x cols` patch grid in
    /// row-major order at `(row + 1, col + 1)`.
    pub fn for_frame(
        special_tokens: usize,
        [rows, cols]: [usize; 2],
        head_dim: usize,
        base: f64,
        site: &ConstantSite,
    ) -> Self {
        assert!(head_dim.is_multiple_of(4), "2D RoPE needs head_dim divisible by 4, got {head_dim}");
        let positions: Vec<[usize; 2]> = std::iter::repeat_n([0, 0], special_tokens)
            .chain((0..rows).flat_map(|r| (0..cols).map(move |c| [r + 1, c + 1])))
            .collect();
        let half = head_dim / 2;
        let inv_freq: Vec<f64> = (0..half / 2).map(|k| base.powf(-((2 * k) as f64) / half as f64)).collect();
        let mut cos = Vec::with_capacity(positions.len() * head_dim);
        let mut sin = Vec::with_capacity(positions.len() * head_dim);
        for pos in &positions {
            for &p in pos {
                // Each half holds its angles twice: [a, a].
                for _ in 0..2 {
                    for f in &inv_freq {
                        let angle = (p as f64 * f) as f32;
                        cos.push(angle.cos());
                        sin.push(angle.sin());
                    }
                }
            }
        }
        let shape = [positions.len(), head_dim];
        Self { cos: site.tensor(cos, shape), sin: site.tensor(sin, shape) }
    }

    /// The same layout repeated for `frames` frames concatenated into one sequence (global attention).
    pub fn repeat_frames(&self, frames: usize) -> Self {
        Self { cos: self.cos.clone().repeat_dim(0, frames), sin: self.sin.clone().repeat_dim(0, frames) }
    }

    pub fn tokens(&self) -> usize {
        self.cos.dims()[0]
    }

    /// Rotates `[batch, heads, tokens, head_dim]` queries or keys.
    pub fn apply(&self, x: Tensor<4>) -> Tensor<4> {
        let [b, h, n, d] = x.dims();
        assert_eq!(n, self.tokens(), "RoPE table covers {} tokens, input has {n}", self.tokens());
        // [b, h, n, axis, part, d/4]: rotate-half inside each axis half.
        let parts = x.clone().reshape([b, h, n, 2, 2, d / 4]);
        let first = parts.clone().narrow(4, 0, 1);
        let second = parts.narrow(4, 1, 1);
        let rotated = Tensor::cat(vec![second.neg(), first], 4).reshape([b, h, n, d]);
        let cos = self.cos.clone().unsqueeze::<4>();
        let sin = self.sin.clone().unsqueeze::<4>();
        x * cos + rotated * sin
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    #[test]
    fn special_tokens_are_unrotated_and_norm_is_kept() {
        let device = Device::flex();
        let table = RopeTable::for_frame(2, [2, 3], 8, 100.0, &ConstantSite::f32(&device));
        let values: Vec<f32> = (0..8 * 8).map(|i| (i as f32 * 0.37).sin()).collect();
        let x = Tensor::<4>::from_data(TensorData::new(values, [1, 1, 8, 8]), &device);
        let y = table.apply(x.clone());
        let diff: Vec<f32> = (y.clone() - x.clone()).narrow(2, 0, 2).into_data().try_to_vec::<f32>().unwrap();
        assert!(diff.iter().all(|v| v.abs() < 1e-7));
        let nx: Vec<f32> = x.powi_scalar(2).sum_dim(3).into_data().try_to_vec::<f32>().unwrap();
        let ny: Vec<f32> = y.powi_scalar(2).sum_dim(3).into_data().try_to_vec::<f32>().unwrap();
        for (a, b) in nx.iter().zip(&ny) {
            assert!((a - b).abs() < 1e-5);
        }
    }

    #[test]
    fn first_frequency_rotates_by_row_and_col() {
        let device = Device::flex();
        let table = RopeTable::for_frame(0, [1, 2], 8, 100.0, &ConstantSite::f32(&device));
        // Token 1 sits at (y, x) = (1, 2). Unit vector on feature 0 (y half, first frequency).
        let mut v = vec![0.0f32; 16];
        v[8] = 1.0;
        let x = Tensor::<4>::from_data(TensorData::new(v, [1, 1, 2, 8]), &device);
        let y: Vec<f32> = table.apply(x).into_data().try_to_vec::<f32>().unwrap();
        assert!((y[8] - 1.0f32.cos()).abs() < 1e-6);
        // rotate_half sends feature 0 to feature 2 (the second part of the y half) with + sign.
        assert!((y[8 + 2] - 1.0f32.sin()).abs() < 1e-6);
    }
}
