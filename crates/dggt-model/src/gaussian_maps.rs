//! Per-pixel Gaussian parameters from the Gaussian head's 12 raw channels, activated as the release does:
//! colour `sigmoid` [0:3], opacity `sigmoid` [3], scale `0.1 * softplus` [4:7] (linear scales), rotation
//! L2-normalised [7:11] (read as wxyz by the rasteriser), and the lifespan `gamma = 1 / (relu(x) + 1e-6)`
//! from channel 11 (exactly 1e6 wherever `x <= 0`). A head with velocity channels
//! ([`crate::config::GaussianHeadConfig::velocity`]) has three more, 12-14, read linearly.

use burn::tensor::Tensor;
use burn::tensor::activation::{relu, sigmoid, softplus};

/// Number of raw channels the Gaussian head produces.
pub const GAUSSIAN_CHANNELS: usize = 12;

/// Activated maps, all over `[B, S, H, W, ..]`.
#[derive(Debug, Clone)]
pub struct GaussianMaps {
    /// `[B, S, H, W, 3]` RGB in (0, 1).
    pub rgb: Tensor<5>,
    /// `[B, S, H, W]`.
    pub opacity: Tensor<4>,
    /// `[B, S, H, W, 3]` linear scales.
    pub scale: Tensor<5>,
    /// `[B, S, H, W, 4]` unit quaternions, wxyz.
    pub rotation: Tensor<5>,
    /// `[B, S, H, W]` pre-activation lifespan channel.
    pub lifespan_raw: Tensor<4>,
    /// `[B, S, H, W]` lifespan `gamma` (`gs_conf` in the release).
    pub lifespan: Tensor<4>,
    /// `[B, S, H, W, 3]` velocity in world units per log frame along each view's camera axes (OpenCV), from a
    /// head with velocity channels.
    pub velocity: Option<Tensor<5>>,
}

impl GaussianMaps {
    /// Activates a raw `[B, S, H, W, 12]` head output (`[.., 15]` with velocity channels).
    pub fn from_raw(raw: Tensor<5>) -> Self {
        let channels_in = raw.dims()[4];
        assert!(
            channels_in == GAUSSIAN_CHANNELS || channels_in == GAUSSIAN_CHANNELS + 3,
            "the Gaussian head has {GAUSSIAN_CHANNELS} channels, or three more for velocity; got {channels_in}"
        );
        let channels = |start: usize, count: usize| raw.clone().narrow(4, start, count);
        let rotation = channels(7, 4);
        // The release divides by max(|q|, 1e-12). Clamping the squared norm before the square root gives the
        // same values and a zero (not NaN) gradient for an all-zero quaternion, where sqrt's derivative is infinite.
        let norm = rotation.clone().powi_scalar(2).sum_dim(4).clamp_min(1e-24).sqrt();
        let lifespan_raw = channels(11, 1).squeeze_dim::<4>(4);
        Self {
            rgb: sigmoid(channels(0, 3)),
            opacity: sigmoid(channels(3, 1)).squeeze_dim::<4>(4),
            scale: softplus(channels(4, 3), 1.0).mul_scalar(0.1),
            rotation: rotation / norm,
            lifespan: relu(lifespan_raw.clone()).add_scalar(1e-6).recip(),
            lifespan_raw,
            velocity: (channels_in > GAUSSIAN_CHANNELS).then(|| raw.narrow(4, GAUSSIAN_CHANNELS, 3)),
        }
    }

    /// The release's `gs_map`: `[rgb, opacity, scale, rotation]`, `[B, S, H, W, 11]`.
    pub fn gs_map(&self) -> Tensor<5> {
        Tensor::cat(
            vec![self.rgb.clone(), self.opacity.clone().unsqueeze_dim(4), self.scale.clone(), self.rotation.clone()],
            4,
        )
    }
}
