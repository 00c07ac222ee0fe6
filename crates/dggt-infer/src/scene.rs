//! The 4D scene of one forward pass: every input pixel's Gaussian placed with its view's camera (moving with
//! the predicted velocities when the network predicts them), the sky Gaussians coloured from the input images,
//! and how targets are assembled and rasterised. Any target view at any time renders from it.

use burn::tensor::Tensor;
use dggt_geom::PosedCamera;
use dggt_model::Dggt;
use dggt_model::sky::SkyGaussians;
use dggt_scene::{
    AssembledGaussians, AssemblySettings, InputView, MeansGradient, PixelGaussians, TargetView, Timeline, ViewRender,
    assemble, interpolate_camera, render_assembled, render_target,
};

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

/// One forward pass's Gaussians, ready to render at any time.
#[derive(Debug, Clone)]
pub struct Scene4d {
    pub pixels: PixelGaussians,
    pub sky: Option<SkyGaussians>,
    pub assembly: AssemblySettings,
}

impl Scene4d {
    /// The scene of `prediction` over `views` (one per input frame of `images`, `[1, S, 3, H, W]` in `[0, 1]`,
    /// which colour the sky); `None` when the network has no Gaussian head.
    pub fn build(
        model: &Dggt,
        prediction: &Prediction,
        images: &Tensor<5>,
        views: Vec<InputView>,
        timeline: &Timeline,
        options: &SceneOptions,
    ) -> Result<Option<Self>, InferError> {
        let Some(maps) = &prediction.gaussians else { return Ok(None) };
        let pixels = PixelGaussians::new(
            maps,
            prediction.depth.clone(),
            prediction.dynamic_logit.clone(),
            views,
            options.means_gradient,
            model.unproject_at,
        )?;
        let pixels = match &prediction.velocity {
            Some(velocity) => pixels.with_motion(velocity.clone(), timeline.frames_per_time())?,
            None => pixels,
        };
        let sky = match (&model.sky_model, options.sky) {
            (Some(sky_model), SkyChoice::Render) => {
                let [_, s, c, h, w] = images.dims();
                let cameras: Vec<_> =
                    pixels.views.iter().map(|v| (v.camera.world_from_camera.inverse(), v.camera.intrinsics)).collect();
                Some(sky_model.gaussians(images.clone().reshape([s, c, h, w]), &cameras))
            }
            _ => None,
        };
        Ok(Some(Self { pixels, sky, assembly: options.assembly }))
    }

    /// The input views the Gaussians were placed with.
    pub fn views(&self) -> &[InputView] {
        &self.pixels.views
    }

    /// The camera of `rig_camera` at scene time `time`, interpolated between its input views.
    pub fn camera_at(&self, rig_camera: usize, time: f64) -> Result<PosedCamera, InferError> {
        Ok(interpolate_camera(&self.pixels.views, rig_camera, time)?)
    }

    /// Assembles and renders `target` over the sky.
    pub fn render(&self, target: &TargetView) -> Result<ViewRender, InferError> {
        Ok(render_target(&self.pixels, self.sky.as_ref(), target, &self.assembly)?)
    }

    /// The first half of [`Scene4d::render`]: the Gaussians visible at `target`.
    pub fn assemble(&self, target: &TargetView) -> Result<AssembledGaussians, InferError> {
        Ok(assemble(&self.pixels, target, &self.assembly)?)
    }

    /// The second half of [`Scene4d::render`]: Gaussians assembled for `target`, rasterised over the sky.
    pub fn render_assembled(
        &self,
        assembled: &AssembledGaussians,
        target: &TargetView,
    ) -> Result<ViewRender, InferError> {
        Ok(render_assembled(assembled, self.sky.as_ref(), target, self.pixels.size, &self.assembly)?)
    }
}
