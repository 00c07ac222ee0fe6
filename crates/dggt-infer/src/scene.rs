//! The 4D scene of one forward pass ([`dggt_scene::Scene4d`]) built from the network's outputs: every input
//! pixel's Gaussian placed with its view's camera (moving with the predicted velocities when the network
//! predicts them, or with the objects found among them, or along the flow head's learnt flow, when the assembly
//! asks) and the sky Gaussians coloured from the input images, as the options choose.

use burn::tensor::Tensor;
use dggt_model::Dggt;
use dggt_scene::{AssemblySettings, InputView, MeansGradient, PixelGaussians, Scene4d, Timeline};

use crate::error::InferError;
use crate::forward::Prediction;

/// Whether the sky model's Gaussians are built and composited behind the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SkyChoice {
    /// When the network has a sky model.
    #[default]
    Render,
    /// Never: the background is black.
    Skip,
}

/// How a scene is built from a forward pass and rendered.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SceneOptions {
    /// Whether rendering losses reach the depth through the means (training); inference detaches them.
    pub means_gradient: MeansGradient,
    pub sky: SkyChoice,
    pub assembly: AssemblySettings,
}

impl Prediction {
    /// The 4D scene of this prediction over `views` (one per input frame of `images`, `[1, S, 3, H, W]` in
    /// `[0, 1]`, which colour the sky); `None` when the network has no Gaussian head.
    pub fn scene(
        &self,
        model: &Dggt,
        images: &Tensor<5>,
        views: Vec<InputView>,
        timeline: &Timeline,
        options: &SceneOptions,
    ) -> Result<Option<Scene4d>, InferError> {
        let Some(maps) = &self.gaussians else { return Ok(None) };
        let pixels = PixelGaussians::new(
            maps,
            self.depth.clone(),
            self.dynamic_logit.clone(),
            views,
            options.means_gradient,
            model.unproject_at,
        )?;
        let pixels = match &self.velocity {
            Some(velocity) => pixels.with_motion(velocity.clone(), timeline.frames_per_time())?,
            None => pixels,
        };
        let flow = match (&model.flow_head, &self.flow_features) {
            (Some(head), Some(features)) => Some((head, features.as_slice())),
            _ => None,
        };
        let pixels = pixels.with_motion_found(options.assembly.dynamic_motion, &options.assembly.instances, flow)?;
        let sky = match (&model.sky_model, options.sky) {
            (Some(sky_model), SkyChoice::Render) => {
                let [_, s, c, h, w] = images.dims();
                let cameras: Vec<_> =
                    pixels.views.iter().map(|v| (v.camera.world_from_camera.inverse(), v.camera.intrinsics)).collect();
                Some(sky_model.gaussians(images.clone().reshape([s, c, h, w]), &cameras))
            }
            _ => None,
        };
        Ok(Some(Scene4d { pixels, sky, assembly: options.assembly }))
    }
}
