//! The `[model]` and `[render]` sections of a training configuration: which network a run trains and how its
//! scenes are rendered. They describe a trained network as much as its training, so inference reads them too:
//! [`TrainedSettings`] takes them (and the preprocessing) from a training `.toml` given as `--config`.

use std::path::{Path, PathBuf};

use dggt_data::Preprocess;
use dggt_flow_head::FlowHeadShape;
use dggt_geom::PixelConvention;
use dggt_model::{ModelConfig, Preset};
use dggt_scene::{AssemblySettings, DynamicBlend, DynamicMotion, InstanceSettings, MeansGradient};
use serde::{Deserialize, Serialize};

use crate::error::InferError;

/// Which network, and where its starting weights come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelSection {
    /// `tiny`, `vggt_1b` or `dggt` (the released architecture).
    pub preset: Preset,
    /// Starting weights: a file with the release's key names (`.pt`, `.pth`, `.safetensors`: a VGGT-1B
    /// checkpoint, the Gaussian heads then starting fresh, or the DGGT release), or a trainer checkpoint of this
    /// project (a `step-N` folder, a run's `checkpoints/` folder or the run folder), whose parameters are carried
    /// over by module path into this network (which may add modules). `None` starts from random weights.
    pub init_checkpoint: Option<PathBuf>,
    /// Parameters the starting checkpoint may lack, as glob patterns over module paths (`gs_head.*`): they
    /// start fresh. Any other parameter the checkpoint lacks is an error naming it, so a wrong file never
    /// silently trains from random weights.
    pub init_may_lack: Vec<String>,
    /// Turn on the Gaussian head's colour skip (`GaussianHeadConfig::color_skip`; off in the release).
    pub color_skip: bool,
    /// Where Gaussian means are unprojected (`GaussianHeadConfig::unproject_at`): `integer` (the release's
    /// convention, required by its weights) or `centred` (pixel centres, for training from scratch).
    pub unproject_at: PixelConvention,
    /// Sky Gaussians per side (`SkyConfig::resolution`, `resolution^2` in all) instead of the preset's; only
    /// for a sky model that starts fresh, since a checkpoint's sky buffers fix their count.
    pub sky_resolution: Option<usize>,
    /// Add the motion head (`ModelConfig::motion_head`; not in the release's weights, so it starts fresh from
    /// predicting zero): dynamic Gaussians are moved to each target time by their predicted velocity.
    pub motion_head: bool,
    /// Give the Gaussian head velocity channels (`GaussianHeadConfig::velocity`; not in the release's weights,
    /// so they start at zero): the motion of the dynamic Gaussians for three output channels instead of a head.
    pub gaussian_velocity: bool,
    /// Give every DPT head a convolution of the input pixels (`DptConfig::pixel_skip`; not in the release's
    /// weights, so only for heads that start fresh).
    pub pixel_skip: bool,
    /// Add the learnt scene-flow head (`ModelConfig::flow_head`; not in the release's weights, so it starts
    /// fresh from predicting zero): with `render.dynamic_motion = "learnt"` dynamic Gaussians move along its
    /// displacements between adjacent inputs.
    pub flow_head: bool,
    /// The flow head's shape (`[model.flow]`: hidden width, heads, neighbours, iterations, chunk, inputs); its
    /// feature widths are the network's.
    pub flow: FlowHeadShape,
}

impl Default for ModelSection {
    fn default() -> Self {
        Self {
            preset: Preset::Tiny,
            init_checkpoint: None,
            init_may_lack: Vec::new(),
            color_skip: false,
            unproject_at: PixelConvention::Integer,
            sky_resolution: None,
            motion_head: false,
            gaussian_velocity: false,
            pixel_skip: false,
            flow_head: false,
            flow: FlowHeadShape::default(),
        }
    }
}

impl ModelSection {
    /// The network this section describes: the preset with the section's changes (colour skip, unprojection,
    /// sky resolution, pixel skip, motion head or Gaussian velocity, flow head).
    pub fn architecture(&self) -> ModelConfig {
        let mut config = self.preset.config();
        if let Some(gs) = &mut config.gs_head {
            gs.color_skip = self.color_skip;
            gs.unproject_at = self.unproject_at;
        }
        if let (Some(sky), Some(resolution)) = (&mut config.sky_model, self.sky_resolution) {
            sky.resolution = resolution;
        }
        config.dpt.pixel_skip = self.pixel_skip;
        let config = if self.motion_head { config.with_motion_head() } else { config };
        let config = if self.flow_head { config.with_flow_head(self.flow.clone()) } else { config };
        if self.gaussian_velocity { config.with_gaussian_velocity() } else { config }
    }
}

/// Where the rendered Gaussians are placed and from which cameras they are rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSection {
    /// `predicted`: the camera head's poses (world = first input camera), as at inference. `ground_truth`:
    /// the export's poses expressed in the first input camera's frame (training from scratch, before the
    /// camera head is useful).
    pub cameras: CameraSource,
    /// Whether the rendering losses reach the depth through the Gaussian means (the release detaches them).
    pub means_gradient: MeansGradient,
    /// Also re-render the input views (the release trains on those only; the paper adds 2N targets).
    pub render_inputs: bool,
    /// Render the sky model as the background.
    pub sky: bool,
    /// Camera-space depth beyond which Gaussians are not drawn (gsplat's far plane). A finite bound keeps
    /// depths that nothing supervises from running away (a scene without sky masks pushes its background out).
    pub far_plane: f64,
    /// Which input views' dynamic Gaussians a target shows: `nearest` (the release) or `cross_fade` (the two
    /// bracketing views, opacities weighted by time).
    pub dynamic_blend: DynamicBlend,
    /// How those dynamic Gaussians reach a target's time: `velocity` (the predicted velocities when the network
    /// has them, else held where predicted), `held` (where predicted, velocities or not) or `instances` (the dynamic pixels grouped into objects, each moved
    /// rigidly along its trajectory through the inputs; `[render.instances]` tunes how they are found).
    pub dynamic_motion: DynamicMotion,
    /// How moving objects are found when `dynamic_motion = "instances"`.
    pub instances: InstanceSettings,
    /// The rasteriser's low-pass variance in pixels² (`eps2d`; 0.3 in the release, whose weights assume it).
    /// A model trained from scratch renders sharper with a smaller one.
    pub eps2d: f64,
}

impl RenderSection {
    /// How targets are assembled and rasterised under these settings (training, and the reconstructions and
    /// evaluations of a model trained with them).
    pub fn assembly(&self) -> AssemblySettings {
        AssemblySettings {
            far_plane: self.far_plane as f32,
            dynamic_blend: self.dynamic_blend,
            dynamic_motion: self.dynamic_motion,
            instances: self.instances,
            eps2d: self.eps2d as f32,
            ..AssemblySettings::default()
        }
    }
}

impl Default for RenderSection {
    fn default() -> Self {
        Self {
            cameras: CameraSource::Predicted,
            means_gradient: MeansGradient::Detached,
            render_inputs: true,
            sky: true,
            far_plane: 1e10,
            dynamic_blend: DynamicBlend::Nearest,
            dynamic_motion: DynamicMotion::Velocity,
            instances: InstanceSettings::default(),
            eps2d: 0.3,
        }
    }
}

/// Where the input views' cameras come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraSource {
    Predicted,
    GroundTruth,
}

/// What inference takes from a training configuration: its network, its rendering and its preprocessing. Other
/// sections are not read.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default)]
pub struct TrainedSettings {
    pub model: ModelSection,
    pub render: RenderSection,
    data: PreprocessOnly,
}

#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default)]
struct PreprocessOnly {
    preprocess: Preprocess,
}

impl TrainedSettings {
    /// Reads the sections of the training configuration at `path`.
    pub fn load(path: &Path) -> Result<Self, InferError> {
        let fail = |detail: String| InferError::Config { path: PathBuf::from(path), detail };
        let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
        toml::from_str(&text).map_err(|e| fail(e.to_string()))
    }

    pub fn preprocess(&self) -> &Preprocess {
        &self.data.preprocess
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instance_motion_is_chosen_and_tuned_in_the_render_section() {
        let text =
            "dynamic_motion = \"instances\"\n[instances.cluster]\nmin_pixels = 4\n[instances.link]\ngate = 2.5\n";
        let render: RenderSection = toml::from_str(text).unwrap();
        let assembly = render.assembly();
        assert_eq!(assembly.dynamic_motion, DynamicMotion::Instances);
        assert_eq!(assembly.instances.cluster.min_pixels, 4);
        assert_eq!(assembly.instances.link.gate, 2.5);
        assert_eq!(assembly.instances.registration, InstanceSettings::default().registration);
        assert_eq!(RenderSection::default().assembly().dynamic_motion, DynamicMotion::Velocity);
        let misspelt = toml::from_str::<RenderSection>("[instances.cluster]\nmin_pixel = 4\n");
        assert!(misspelt.unwrap_err().to_string().contains("min_pixel"));
    }
}
