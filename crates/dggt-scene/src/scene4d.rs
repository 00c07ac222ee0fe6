//! The 4D scene of one forward pass as one value: every input pixel's Gaussians (moving with their velocities
//! when the network predicts them), the sky Gaussians, and the assembly settings; any target view at any time
//! renders from it. Building it from a network's outputs is `dggt-infer`'s (`Prediction::scene`).

use burn::tensor::Tensor;
use dggt_geom::PosedCamera;
use dggt_model::sky::SkyGaussians;
use dggt_splat::DepthStatistic;

use crate::assemble::{AssembledGaussians, AssemblySettings, assemble};
use crate::compose::{ViewRender, render_assembled, render_depth, render_target, render_targets};
use crate::error::SceneError;
use crate::pixels::PixelGaussians;
use crate::timeline::{InputView, TargetView, interpolate_camera};

/// One forward pass's Gaussians, ready to render at any time.
#[derive(Debug, Clone)]
pub struct Scene4d {
    pub pixels: PixelGaussians,
    /// The sky's Gaussians, composited behind the scene; `None` renders a black background.
    pub sky: Option<SkyGaussians>,
    pub assembly: AssemblySettings,
}

impl Scene4d {
    /// The input views the Gaussians were placed with.
    pub fn views(&self) -> &[InputView] {
        &self.pixels.views
    }

    /// The camera of `rig_camera` at scene time `time`, interpolated between its input views.
    pub fn camera_at(&self, rig_camera: usize, time: f64) -> Result<PosedCamera, SceneError> {
        interpolate_camera(&self.pixels.views, rig_camera, time)
    }

    /// Assembles and renders `target` over the sky.
    pub fn render(&self, target: &TargetView) -> Result<ViewRender, SceneError> {
        render_target(&self.pixels, self.sky.as_ref(), target, &self.assembly)
    }

    /// [`Scene4d::render`] for each of `targets`, their skies rasterised together.
    pub fn render_all(&self, targets: &[TargetView]) -> Result<Vec<ViewRender>, SceneError> {
        render_targets(&self.pixels, self.sky.as_ref(), targets, &self.assembly)
    }

    /// The first half of [`Scene4d::render`]: the Gaussians visible at `target`.
    pub fn assemble(&self, target: &TargetView) -> Result<AssembledGaussians, SceneError> {
        assemble(&self.pixels, target, &self.assembly)
    }

    /// The second half of [`Scene4d::render`]: Gaussians assembled for `target`, rasterised over the sky.
    pub fn render_assembled(
        &self,
        assembled: &AssembledGaussians,
        target: &TargetView,
    ) -> Result<ViewRender, SceneError> {
        render_assembled(assembled, self.sky.as_ref(), target, self.pixels.size, &self.assembly)
    }

    /// The foreground's depth of Gaussians assembled for `target`, as `statistic` says ([`render_depth`]).
    pub fn render_depth(
        &self,
        assembled: &AssembledGaussians,
        target: &TargetView,
        statistic: DepthStatistic,
    ) -> Result<Tensor<3>, SceneError> {
        render_depth(assembled, target, self.pixels.size, &self.assembly, statistic)
    }
}
