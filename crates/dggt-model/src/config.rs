//! Network hyper-parameters: every size the DGGT network is built from, as serde structs.
//!
//! Field names follow the parity vectors' `config.json`, so [`ModelConfig::from_parity_json`] reads that file
//! directly (unknown fields are ignored). Presets give the tiny parity model and the full VGGT-1B / DGGT sizes.

use std::path::Path;

use dggt_geom::PixelConvention;
use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::gaussian_maps::GAUSSIAN_CHANNELS;

/// ImageNet normalisation the aggregator applies to `[0, 1]` RGB input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageNormalization {
    pub mean: [f64; 3],
    pub std: [f64; 3],
}

impl Default for ImageNormalization {
    fn default() -> Self {
        Self { mean: [0.485, 0.456, 0.406], std: [0.229, 0.224, 0.225] }
    }
}

/// The DINOv2 ViT (with registers) used as the aggregator's patch embedding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DinoConfig {
    /// Image size the positional embedding was trained for (square); the grid is `img_size / patch_size`.
    pub img_size: usize,
    pub patch_size: usize,
    pub embed_dim: usize,
    pub depth: usize,
    pub num_heads: usize,
    pub mlp_ratio: f64,
    pub num_register_tokens: usize,
    /// Whether the positional-embedding resize uses PyTorch's antialiased bicubic kernel.
    pub interpolate_antialias: bool,
    /// DINOv2's historical offset: when non-zero the resize is driven by a scale factor
    /// `(grid + offset) / M` instead of the output size.
    pub interpolate_offset: f64,
    /// LayerNorm epsilon of every DINO norm (blocks and final norm).
    pub norm_eps: f64,
}

impl DinoConfig {
    pub fn mlp_hidden(&self) -> usize {
        (self.embed_dim as f64 * self.mlp_ratio) as usize
    }

    /// Side of the square positional-embedding grid.
    pub fn pos_embed_grid(&self) -> usize {
        self.img_size / self.patch_size
    }
}

/// The alternating frame/global attention aggregator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AggregatorConfig {
    pub img_size: usize,
    pub patch_size: usize,
    pub embed_dim: usize,
    /// Number of frame blocks (and, equally, of global blocks).
    pub depth: usize,
    pub num_heads: usize,
    pub mlp_ratio: f64,
    pub num_register_tokens: usize,
    pub qk_norm: bool,
    pub qk_norm_eps: f64,
    pub block_norm_eps: f64,
    /// Base of the 2D RoPE frequencies; 0 disables RoPE.
    pub rope_freq: f64,
    #[serde(default)]
    pub image_normalization: ImageNormalization,
    pub dino: DinoConfig,
}

impl AggregatorConfig {
    pub fn head_dim(&self) -> usize {
        self.embed_dim / self.num_heads
    }

    pub fn mlp_hidden(&self) -> usize {
        (self.embed_dim as f64 * self.mlp_ratio) as usize
    }

    /// Index of the first patch token in a frame: camera token, then the registers.
    pub fn patch_start_idx(&self) -> usize {
        1 + self.num_register_tokens
    }
}

/// Activation applied to one part of the `absT_quaR_FoV` pose encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PoseActivation {
    Linear,
    Relu,
    Exp,
}

/// The iterative camera head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraHeadConfig {
    /// Width of the aggregated tokens it reads (twice the aggregator width).
    pub dim_in: usize,
    pub trunk_depth: usize,
    pub num_heads: usize,
    pub mlp_ratio: f64,
    /// Epsilon of `token_norm`, `trunk_norm` and the trunk blocks' norms.
    pub block_norm_eps: f64,
    /// Epsilon of the affine-free modulation norm.
    pub adaln_eps: f64,
    /// Length of the pose encoding (9 for `absT_quaR_FoV`).
    pub target_dim: usize,
    /// `[input, hidden, output]` widths of the pose branch MLP.
    pub pose_branch: [usize; 3],
    pub trans_act: PoseActivation,
    pub quat_act: PoseActivation,
    pub fl_act: PoseActivation,
    pub num_iterations: usize,
}

impl CameraHeadConfig {
    pub fn mlp_hidden(&self) -> usize {
        (self.dim_in as f64 * self.mlp_ratio) as usize
    }
}

/// Settings shared by every DPT head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DptConfig {
    pub patch_size: usize,
    pub features: usize,
    pub out_channels: [usize; 4],
    pub intermediate_layer_idx: [usize; 4],
    pub pos_embed: bool,
    pub head_features_2: usize,
    pub layernorm_eps: f64,
    /// Adds a 3x3 convolution of the input image (RGB in `[0, 1]`) to every head's full-resolution features
    /// before `output_conv2`: depth, Gaussian and mask edges can then follow image edges, which a map upsampled
    /// from 14-pixel patch tokens blurs. For models trained from scratch; off in the release (its checkpoints
    /// have no such layer).
    #[serde(default)]
    pub pixel_skip: bool,
}

/// Activation of a DPT head's prediction or confidence channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadActivation {
    Linear,
    Exp,
    /// `1 + exp(x)`.
    Expp1,
    Sigmoid,
    /// `sign(x) * (exp(|x|) - 1)`.
    InvLog,
}

/// One DPT head's own settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DptHeadConfig {
    pub dim_in: usize,
    /// Raw output channels: prediction channels, then one confidence channel.
    pub output_dim: usize,
    pub activation: HeadActivation,
    pub conf_activation: HeadActivation,
}

/// The Gaussian head: a DPT head over `[DINO block 0 | frame | global]` tokens whose channels are
/// activated as Gaussian parameters (colour, opacity, scale, rotation, lifespan).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaussianHeadConfig {
    pub dim_in: usize,
    pub output_dim: usize,
    /// Adds each input pixel's colour logit to the colour channels, `rgb = sigmoid(raw + logit(pixel))`: a
    /// per-pixel path from the image to the Gaussian colours that 14-pixel patch tokens lack, so a small model
    /// trained from scratch starts from the observed colours. Off in the release (its checkpoints assume so).
    #[serde(default)]
    pub color_skip: bool,
    /// Where each pixel's Gaussian mean is unprojected from its depth: at integer pixel coordinates, as the
    /// release does (its weights assume it; a Gaussian then lands half a pixel off its pixel's centre in its
    /// own view), or at pixel centres, where the rasteriser samples (for models trained from scratch).
    #[serde(default = "release_unprojection")]
    pub unproject_at: PixelConvention,
    /// Three more output channels, 12-14: each pixel's 3D velocity in world units per log frame along its
    /// view's camera axes (OpenCV), the motion of the dynamic Gaussians from a head that runs anyway (where
    /// [`ModelConfig::motion_head`] adds a whole DPT head). Not in the release; they start at zero.
    #[serde(default)]
    pub velocity: bool,
}

fn release_unprojection() -> PixelConvention {
    PixelConvention::Integer
}

/// The sky model: `resolution^2` Gaussians on a hemisphere of `radius` (the points themselves are checkpoint
/// buffers; `radius` documents where they lie).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkyConfig {
    pub resolution: usize,
    pub radius: f64,
}

/// A named architecture: the tiny parity model, VGGT-1B, or the released DGGT network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Preset {
    #[serde(rename = "tiny")]
    Tiny,
    #[serde(rename = "vggt_1b")]
    Vggt1b,
    #[serde(rename = "dggt")]
    Dggt,
}

impl Preset {
    pub const ALL: [Self; 3] = [Self::Tiny, Self::Vggt1b, Self::Dggt];

    /// The name used in configurations and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tiny => "tiny",
            Self::Vggt1b => "vggt_1b",
            Self::Dggt => "dggt",
        }
    }

    /// The preset's network.
    pub fn config(self) -> ModelConfig {
        match self {
            Self::Tiny => ModelConfig::tiny(),
            Self::Vggt1b => ModelConfig::vggt_1b(),
            Self::Dggt => ModelConfig::dggt(),
        }
    }
}

impl std::fmt::Display for Preset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Preset {
    type Err = ModelError;

    fn from_str(name: &str) -> Result<Self, ModelError> {
        Self::ALL.into_iter().find(|p| p.name() == name).ok_or_else(|| {
            let known: Vec<&str> = Self::ALL.iter().map(|p| p.name()).collect();
            ModelError::Config(format!("unknown preset `{name}` (known: {})", known.join(", ")))
        })
    }
}

/// The whole network. The point head is VGGT's; the Gaussian, instance (dynamic) and semantic heads exist
/// in DGGT only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    pub aggregator: AggregatorConfig,
    pub camera_head: CameraHeadConfig,
    #[serde(rename = "dpt_common")]
    pub dpt: DptConfig,
    pub depth_head: DptHeadConfig,
    pub point_head: DptHeadConfig,
    #[serde(default)]
    pub gs_head: Option<GaussianHeadConfig>,
    #[serde(default)]
    pub instance_head: Option<DptHeadConfig>,
    #[serde(default)]
    pub semantic_head: Option<DptHeadConfig>,
    #[serde(default)]
    pub sky_model: Option<SkyConfig>,
    /// This project's motion head (the paper trains one; the release ships none): per-pixel 3D velocity of
    /// the dynamic Gaussians from the aggregator's frame and global tokens (`dim_in = 2 C`, 3 velocity
    /// channels and an unused last channel). See [`crate::model::Dggt::motion_head`].
    #[serde(default)]
    pub motion_head: Option<DptHeadConfig>,
    /// This project's learnt scene-flow head F(ta, tb) (the paper's; the release ships none): each dynamic
    /// pixel's displacement to the neighbouring input time of its camera, from the Gaussian head's features
    /// ([`ModelConfig::flow_features`]). See [`crate::model::Dggt::flow_head`].
    #[serde(default)]
    pub flow_head: Option<dggt_flow_head::FlowHeadConfig>,
}

impl ModelConfig {
    /// Reads the parity folder's `config.json` (only the fields above are used) and validates it.
    pub fn from_parity_json(path: impl AsRef<Path>) -> Result<Self, ModelError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|source| ModelError::Io { path: path.display().to_string(), source })?;
        Self::from_json_str(&text)
    }

    /// Parses a configuration in the `config.json` layout and validates it.
    pub fn from_json_str(text: &str) -> Result<Self, ModelError> {
        let config: Self = serde_json::from_str(text).map_err(|e| ModelError::Config(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// The tiny model of the parity vectors `dggt_tiny_s3_56x70`.
    pub fn tiny() -> Self {
        let dino = DinoConfig {
            img_size: 56,
            patch_size: 14,
            embed_dim: 64,
            depth: 4,
            num_heads: 4,
            mlp_ratio: 4.0,
            num_register_tokens: 4,
            interpolate_antialias: true,
            interpolate_offset: 0.0,
            norm_eps: 1e-6,
        };
        Self::with_sizes(dino, 4, 4, 1, 32, [16, 32, 64, 64], [0, 1, 2, 3]).with_dggt_heads(20)
    }

    /// VGGT-1B: ViT-L/14 DINO, 24+24 aggregator blocks, DPT features 256.
    pub fn vggt_1b() -> Self {
        let dino = DinoConfig {
            img_size: 518,
            patch_size: 14,
            embed_dim: 1024,
            depth: 24,
            num_heads: 16,
            mlp_ratio: 4.0,
            num_register_tokens: 4,
            interpolate_antialias: true,
            interpolate_offset: 0.0,
            norm_eps: 1e-6,
        };
        let mut config = Self::with_sizes(dino, 24, 16, 4, 256, [256, 512, 1024, 1024], [4, 11, 17, 23]);
        config.depth_head.conf_activation = HeadActivation::Expp1;
        config
    }

    /// The DGGT release: the VGGT-1B sizes; its depth confidence is a sigmoid (VGGT: `1 + exp`).
    pub fn dggt() -> Self {
        let mut config = Self::vggt_1b().with_dggt_heads(300);
        config.depth_head.conf_activation = HeadActivation::Sigmoid;
        config
    }

    /// Adds the motion head ([`ModelConfig::motion_head`]), linear outputs.
    pub fn with_motion_head(mut self) -> Self {
        self.motion_head = Some(DptHeadConfig {
            dim_in: 2 * self.aggregator.embed_dim,
            output_dim: 4,
            activation: HeadActivation::Linear,
            conf_activation: HeadActivation::Linear,
        });
        self
    }

    /// Adds the learnt scene-flow head ([`ModelConfig::flow_head`]) of `shape`, reading the Gaussian
    /// head's features ([`ModelConfig::flow_features`]).
    pub fn with_flow_head(mut self, shape: dggt_flow_head::FlowHeadShape) -> Self {
        let feature_widths = self.flow_features();
        self.flow_head = Some(dggt_flow_head::FlowHeadConfig { feature_widths, shape });
        self
    }

    /// The channels of the Gaussian head's maps the flow head reads, in order: its four resampled token maps
    /// (strides 4, 8, 14 and 28 pixels per cell at the patch grid's scale) and its full-resolution features
    /// (`head_in`, with the pixel skip when the network has one).
    pub fn flow_features(&self) -> Vec<usize> {
        let mut widths = self.dpt.out_channels.to_vec();
        widths.push(self.dpt.features / 2);
        widths
    }

    /// Whether the network predicts velocities: a motion head, or a Gaussian head with velocity channels.
    pub fn predicts_motion(&self) -> bool {
        self.motion_head.is_some() || self.gs_head.as_ref().is_some_and(|gs| gs.velocity)
    }

    /// Gives the Gaussian head its velocity channels ([`GaussianHeadConfig::velocity`]); unchanged without one.
    pub fn with_gaussian_velocity(mut self) -> Self {
        if let Some(gs) = &mut self.gs_head {
            gs.velocity = true;
            gs.output_dim = GAUSSIAN_CHANNELS + 3;
        }
        self
    }

    /// Adds DGGT's Gaussian (12 channels), instance (2) and semantic (11) heads and its sky model.
    fn with_dggt_heads(mut self, sky_resolution: usize) -> Self {
        let c = self.aggregator.embed_dim;
        let dino_head = |output_dim| DptHeadConfig {
            dim_in: c,
            output_dim,
            activation: HeadActivation::Linear,
            conf_activation: HeadActivation::Expp1,
        };
        self.gs_head = Some(GaussianHeadConfig {
            dim_in: 3 * c,
            output_dim: GAUSSIAN_CHANNELS,
            color_skip: false,
            unproject_at: release_unprojection(),
            velocity: false,
        });
        self.instance_head = Some(dino_head(2));
        self.semantic_head = Some(dino_head(11));
        self.sky_model = Some(SkyConfig { resolution: sky_resolution, radius: 50.0 });
        self
    }

    fn with_sizes(
        dino: DinoConfig,
        depth: usize,
        num_heads: usize,
        camera_trunk_depth: usize,
        features: usize,
        out_channels: [usize; 4],
        intermediate_layer_idx: [usize; 4],
    ) -> Self {
        let embed_dim = dino.embed_dim;
        let aggregator = AggregatorConfig {
            img_size: dino.img_size,
            patch_size: dino.patch_size,
            embed_dim,
            depth,
            num_heads,
            mlp_ratio: 4.0,
            num_register_tokens: 4,
            qk_norm: true,
            qk_norm_eps: 1e-5,
            block_norm_eps: 1e-5,
            rope_freq: 100.0,
            image_normalization: ImageNormalization::default(),
            dino,
        };
        let dim_in = 2 * embed_dim;
        let camera_head = CameraHeadConfig {
            dim_in,
            trunk_depth: camera_trunk_depth,
            num_heads,
            mlp_ratio: 4.0,
            block_norm_eps: 1e-5,
            adaln_eps: 1e-6,
            target_dim: 9,
            pose_branch: [dim_in, dim_in / 2, 9],
            trans_act: PoseActivation::Linear,
            quat_act: PoseActivation::Linear,
            fl_act: PoseActivation::Relu,
            num_iterations: 4,
        };
        let dpt = DptConfig {
            patch_size: aggregator.patch_size,
            features,
            out_channels,
            intermediate_layer_idx,
            pos_embed: true,
            head_features_2: 32,
            layernorm_eps: 1e-5,
            pixel_skip: false,
        };
        let depth_head = DptHeadConfig {
            dim_in,
            output_dim: 2,
            activation: HeadActivation::Exp,
            conf_activation: HeadActivation::Sigmoid,
        };
        let point_head = DptHeadConfig {
            dim_in,
            output_dim: 4,
            activation: HeadActivation::InvLog,
            conf_activation: HeadActivation::Expp1,
        };
        Self {
            aggregator,
            camera_head,
            dpt,
            depth_head,
            point_head,
            gs_head: None,
            instance_head: None,
            semantic_head: None,
            motion_head: None,
            flow_head: None,
            sky_model: None,
        }
    }

    /// Checks that the sizes fit together.
    pub fn validate(&self) -> Result<(), ModelError> {
        let fail = |msg: String| Err(ModelError::Config(msg));
        let a = &self.aggregator;
        let d = &a.dino;
        if d.embed_dim != a.embed_dim || d.patch_size != a.patch_size {
            return fail(format!(
                "DINO width/patch ({}, {}) differ from the aggregator's ({}, {})",
                d.embed_dim, d.patch_size, a.embed_dim, a.patch_size
            ));
        }
        if !d.embed_dim.is_multiple_of(d.num_heads) || !a.embed_dim.is_multiple_of(a.num_heads) {
            return fail("embed_dim must be divisible by num_heads".into());
        }
        if a.rope_freq > 0.0 && !a.head_dim().is_multiple_of(4) {
            return fail(format!("2D RoPE needs head_dim divisible by 4, got {}", a.head_dim()));
        }
        if d.depth < a.depth {
            return fail(format!("DINO depth {} is smaller than the aggregator depth {}", d.depth, a.depth));
        }
        let c = &self.camera_head;
        if c.dim_in != 2 * a.embed_dim || c.pose_branch[0] != c.dim_in || c.pose_branch[2] != c.target_dim {
            return fail(format!(
                "camera head dim_in {} / pose_branch {:?} / target_dim {} do not fit aggregator width {}",
                c.dim_in, c.pose_branch, c.target_dim, a.embed_dim
            ));
        }
        if c.target_dim != 9 {
            return fail(format!("only the 9-value absT_quaR_FoV pose encoding is supported, got {}", c.target_dim));
        }
        if !c.dim_in.is_multiple_of(c.num_heads) {
            return fail("camera head dim_in must be divisible by num_heads".into());
        }
        let width = a.embed_dim;
        let heads = [
            ("depth_head", Some((self.depth_head.dim_in, self.depth_head.output_dim)), 2 * width, 2),
            ("point_head", Some((self.point_head.dim_in, self.point_head.output_dim)), 2 * width, 2),
            ("gs_head", self.gs_head.as_ref().map(|h| (h.dim_in, h.output_dim)), 3 * width, 12),
            ("instance_head", self.instance_head.as_ref().map(|h| (h.dim_in, h.output_dim)), width, 2),
            ("semantic_head", self.semantic_head.as_ref().map(|h| (h.dim_in, h.output_dim)), width, 2),
            ("motion_head", self.motion_head.as_ref().map(|h| (h.dim_in, h.output_dim)), 2 * width, 4),
        ];
        for (name, sizes, dim_in, min_output) in heads {
            if let Some((head_dim_in, output_dim)) = sizes
                && (head_dim_in != dim_in || output_dim < min_output)
            {
                return fail(format!(
                    "{name} dim_in {head_dim_in} / output_dim {output_dim}: expected dim_in {dim_in} and at \
                     least {min_output} outputs for aggregator width {width}"
                ));
            }
        }
        if let Some(gs) = &self.gs_head
            && gs.velocity
            && gs.output_dim != GAUSSIAN_CHANNELS + 3
        {
            return fail(format!(
                "gs_head with velocity channels has output_dim {}, expected {}",
                gs.output_dim,
                GAUSSIAN_CHANNELS + 3
            ));
        }
        if let Some(flow) = &self.flow_head {
            if self.gs_head.is_none() || self.instance_head.is_none() {
                return fail(
                    "flow_head needs a Gaussian head (its features) and an instance head (its queries)".into(),
                );
            }
            if flow.feature_widths != self.flow_features() {
                return fail(format!(
                    "flow_head feature_widths {:?}: the Gaussian head's maps have {:?} channels",
                    flow.feature_widths,
                    self.flow_features()
                ));
            }
            flow.validate().map_err(|e| ModelError::Config(format!("flow_head: {e}")))?;
        }
        if !self.dpt.features.is_multiple_of(2) || (self.dpt.pos_embed && !(self.dpt.features / 2).is_multiple_of(4)) {
            return fail(format!("DPT features {} must be a multiple of 8", self.dpt.features));
        }
        if self.dpt.intermediate_layer_idx.iter().any(|&i| i >= a.depth.min(d.depth)) {
            return fail(format!(
                "DPT tapped layers {:?} exceed the aggregator depth {}",
                self.dpt.intermediate_layer_idx, a.depth
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate() {
        ModelConfig::tiny().validate().unwrap();
        ModelConfig::vggt_1b().validate().unwrap();
        ModelConfig::dggt().validate().unwrap();
    }

    #[test]
    fn full_size_matches_release_numbers() {
        let c = ModelConfig::dggt();
        assert_eq!(c.aggregator.dino.embed_dim, 1024);
        assert_eq!(c.aggregator.dino.pos_embed_grid(), 37);
        assert_eq!(c.aggregator.depth, 24);
        assert_eq!(c.camera_head.dim_in, 2048);
        assert_eq!(c.camera_head.pose_branch, [2048, 1024, 9]);
        assert_eq!(c.dpt.out_channels, [256, 512, 1024, 1024]);
        assert_eq!(c.dpt.intermediate_layer_idx, [4, 11, 17, 23]);
        assert_eq!(c.depth_head.conf_activation, HeadActivation::Sigmoid);
        assert_eq!(c.gs_head.as_ref().unwrap().dim_in, 3072);
        assert_eq!(c.instance_head.as_ref().unwrap().dim_in, 1024);
        let vggt = ModelConfig::vggt_1b();
        assert_eq!(vggt.depth_head.conf_activation, HeadActivation::Expp1);
        assert!(vggt.gs_head.is_none() && vggt.instance_head.is_none() && vggt.semantic_head.is_none());
    }

    #[test]
    fn json_round_trip() {
        let c = ModelConfig::vggt_1b();
        let text = serde_json::to_string(&c).unwrap();
        assert_eq!(ModelConfig::from_json_str(&text).unwrap(), c);
    }

    #[test]
    fn inconsistent_sizes_are_rejected() {
        let mut c = ModelConfig::tiny();
        c.camera_head.dim_in = 100;
        assert!(c.validate().is_err());
    }
}
