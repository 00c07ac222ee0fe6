//! Rendering one target view: its assembled Gaussians as the foreground, composited over the sky Gaussians
//! rendered from the same camera: `rgb = alpha · foreground + (1 - alpha) · sky` (black without a sky model).
//!
//! With [`HiddenSky::Skip`] the sky is not rendered behind a view whose foreground lets (almost) none of it
//! through; the foreground is then composited over black (`alpha · foreground`), which differs from the exact
//! composite by `(1 - alpha) · sky`, below the tolerance times the sky's colour.
//!
//! Several target views render their foregrounds one by one and their skies together ([`render_targets`]): the
//! same sky Gaussians from every camera in one rasteriser call.
//!
//! The release's inference additionally min-max normalises the sky over all views before [`composite`]
//! (`dggt_parity::network::release_render`); a trained model of this project composites the sky as rendered, in training and
//! inference alike.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics, PosedCamera};
use dggt_model::host::host_f32;
use dggt_model::sky::SkyGaussians;
use dggt_splat::{
    CameraTensors, DepthStatistic, GaussianTensors, OpacityTensor, RasterSettings, RenderSettings, RenderTensors,
    render,
};

use crate::assemble::{
    AssembledGaussians, AssemblyCounts, AssemblySettings, HiddenSky, assemble, assemble_with_velocities,
};
use crate::error::SceneError;
use crate::pixels::PixelGaussians;
use crate::timeline::TargetView;

/// One rendered view.
#[derive(Debug, Clone)]
pub struct ViewRender {
    /// `[H, W, 3]` the final colours.
    pub rgb: Tensor<3>,
    /// `[H, W]` foreground opacity.
    pub alpha: Tensor<3>,
    /// `[H, W]` expected depth of the foreground (0 where empty).
    pub depth: Tensor<3>,
    /// `[H, W, 3]` the sky as rendered, when there is one.
    pub sky: Option<Tensor<3>>,
    pub counts: AssemblyCounts,
}

/// Assembles and renders `target`, over `sky` when given.
pub fn render_target(
    pixels: &PixelGaussians,
    sky: Option<&SkyGaussians>,
    target: &TargetView,
    assembly: &AssemblySettings,
) -> Result<ViewRender, SceneError> {
    let assembled = assemble(pixels, target, assembly)?;
    render_assembled(&assembled, sky, target, pixels.size, assembly)
}

/// Assembles and renders every view of `targets`, over `sky` when given: [`render_target`] for each, with the
/// sky of all of them rasterised in one call (the same sky Gaussians seen from every target camera).
pub fn render_targets(
    pixels: &PixelGaussians,
    sky: Option<&SkyGaussians>,
    targets: &[TargetView],
    assembly: &AssemblySettings,
) -> Result<Vec<ViewRender>, SceneError> {
    let assembled: Vec<AssembledGaussians> =
        targets.iter().map(|target| assemble(pixels, target, assembly)).collect::<Result<_, _>>()?;
    render_all_assembled(&assembled, sky, targets, pixels.size, assembly)
}

/// Renders Gaussians already assembled for `target` (the second half of [`render_target`]), over `sky` when
/// given, at `size`.
pub fn render_assembled(
    assembled: &AssembledGaussians,
    sky: Option<&SkyGaussians>,
    target: &TargetView,
    size: ImageSize,
    assembly: &AssemblySettings,
) -> Result<ViewRender, SceneError> {
    let mut views =
        render_all_assembled(std::slice::from_ref(assembled), sky, std::slice::from_ref(target), size, assembly)?;
    Ok(views.pop().expect("one view rendered for one target"))
}

/// Each `assembled[i]` rendered at `targets[i]` and composited over the sky, the skies of all views that show
/// one rasterised together.
fn render_all_assembled(
    assembled: &[AssembledGaussians],
    sky: Option<&SkyGaussians>,
    targets: &[TargetView],
    size: ImageSize,
    assembly: &AssemblySettings,
) -> Result<Vec<ViewRender>, SceneError> {
    let foregrounds: Vec<RenderTensors> = assembled
        .iter()
        .zip(targets)
        .map(|(assembled, target)| render_foreground(assembled, target, size, assembly))
        .collect::<Result<_, _>>()?;
    let shows_sky: Vec<bool> = match (sky, assembly.hidden_sky) {
        (None, _) => vec![false; targets.len()],
        (Some(_), HiddenSky::Render) => vec![true; targets.len()],
        (Some(_), HiddenSky::Skip { tolerance }) => {
            foregrounds.iter().map(|f| sky_shows_through(&f.alpha, tolerance)).collect::<Result<_, _>>()?
        }
    };
    let mut skies = match sky {
        Some(sky) => render_skies(sky, targets, &shows_sky, size, assembly)?.into_iter(),
        None => Vec::new().into_iter(),
    };
    let squeeze3 = |t: Tensor<4>| t.squeeze_dim::<3>(0);
    let views = foregrounds.into_iter().zip(assembled).zip(&shows_sky).zip(targets);
    Ok(views
        .map(|(((RenderTensors { colors, alpha, depth }, assembled), &shows_sky), target)| {
            let (rgb, sky) = match sky {
                Some(_) if shows_sky => {
                    let sky_rgb = skies.next().expect("one sky rendered per view that shows it");
                    (composite(alpha.clone(), colors, sky_rgb.clone()), Some(sky_rgb))
                }
                Some(_) => {
                    tracing::debug!(time = target.time, "sky hidden by the foreground: not rendered");
                    (colors * alpha.clone().unsqueeze_dim::<4>(3), None)
                }
                None => (colors, None),
            };
            ViewRender { rgb: squeeze3(rgb), alpha, depth, sky: sky.map(squeeze3), counts: assembled.counts }
        })
        .collect())
}

/// The foreground of one target view: `[1, H, W, 3]` colours, `[1, H, W]` alpha and depth.
fn render_foreground(
    assembled: &AssembledGaussians,
    target: &TargetView,
    size: ImageSize,
    assembly: &AssemblySettings,
) -> Result<RenderTensors, SceneError> {
    render_one(&assembled.gaussians, target, size, &foreground_settings(assembly), "the view")
}

/// `gaussians` rasterised from `target`'s camera alone; errors name `what` of which view was rendered.
fn render_one(
    gaussians: &GaussianTensors,
    target: &TargetView,
    size: ImageSize,
    settings: &RenderSettings,
    what: &str,
) -> Result<RenderTensors, SceneError> {
    let cameras = camera_tensors(&[target.camera], size, &gaussians.means.device())?;
    render(gaussians, &cameras, settings).map_err(|source| SceneError::Render {
        what: format!("{what} of camera {} at t = {}", target.rig_camera, target.time),
        source,
    })
}

/// `[1, H, W, 3]` the sky of each target whose `shows_sky` is set, in order, rasterised in one call.
fn render_skies(
    sky: &SkyGaussians,
    targets: &[TargetView],
    shows_sky: &[bool],
    size: ImageSize,
    assembly: &AssemblySettings,
) -> Result<Vec<Tensor<4>>, SceneError> {
    let cameras: Vec<PosedCamera> =
        targets.iter().zip(shows_sky).filter(|&(_, &shows)| shows).map(|(target, _)| target.camera).collect();
    if cameras.is_empty() {
        return Ok(Vec::new());
    }
    let tensors = camera_tensors(&cameras, size, &sky.means.device())?;
    let what = || match targets {
        [target] => format!("the sky of the view of camera {} at t = {}", target.rig_camera, target.time),
        _ => format!("the sky of {} target views", cameras.len()),
    };
    let skies = render(&sky_splats(sky), &tensors, &foreground_settings(assembly))
        .map_err(|source| SceneError::Render { what: what(), source })?
        .colors;
    Ok((0..cameras.len()).map(|v| skies.clone().narrow(0, v, 1)).collect())
}

/// `[H, W]` the foreground's depth of Gaussians already assembled for `target`, as `statistic` says (the
/// median: the surface each pixel sees rather than the blend [`ViewRender::depth`] holds; no gradient). No sky:
/// the depth is the foreground's.
pub fn render_depth(
    assembled: &AssembledGaussians,
    target: &TargetView,
    size: ImageSize,
    assembly: &AssemblySettings,
    statistic: DepthStatistic,
) -> Result<Tensor<3>, SceneError> {
    let mut settings = foreground_settings(assembly);
    settings.raster.depth = statistic;
    Ok(render_one(&assembled.gaussians, target, size, &settings, "the depth")?.depth)
}

/// How the foreground is rasterised under `assembly`: its planes and low-pass, over no background.
fn foreground_settings(assembly: &AssemblySettings) -> RenderSettings {
    let raster = RasterSettings {
        near_plane: assembly.near_plane,
        far_plane: assembly.far_plane,
        eps2d: assembly.eps2d,
        ..Default::default()
    };
    RenderSettings { raster, background: None }
}

/// `[H, W, 3]` the expected world velocity (world units per unit of scene time) of the surface each pixel of
/// `target` sees: the velocities of [`crate::assembled_velocities`] rasterised as colours and divided by the
/// foreground's opacity (zero where nothing is drawn).
pub fn render_flow(
    pixels: &PixelGaussians,
    target: &TargetView,
    assembly: &AssemblySettings,
) -> Result<Tensor<3>, SceneError> {
    let (assembled, velocities) = assemble_with_velocities(pixels, target, assembly)?;
    let velocities: Vec<f32> = velocities.into_iter().flatten().collect();
    let device = assembled.gaussians.means.device();
    let count = velocities.len() / 3;
    let gaussians = GaussianTensors {
        colors: Tensor::from_data(TensorData::new(velocities, [count, 3]), &device),
        ..assembled.gaussians
    };
    let RenderTensors { colors, alpha, .. } =
        render_one(&gaussians, target, pixels.size, &foreground_settings(assembly), "the flow")?;
    let flow = colors / alpha.clamp_min(1e-6).unsqueeze_dim::<4>(3);
    Ok(flow.squeeze_dim::<3>(0))
}

/// Whether the foreground opacity `alpha` lets at least `tolerance` of the background through at any pixel.
fn sky_shows_through(alpha: &Tensor<3>, tolerance: f32) -> Result<bool, SceneError> {
    let least_alpha = host_f32(alpha.clone().min().reshape([1]), "foreground alpha")?[0];
    Ok(!(1.0 - least_alpha < tolerance))
}

/// `[V, H, W, 3]` foreground colours over the background: `alpha · foreground + (1 - alpha) · background`, with
/// `alpha` `[V, H, W]` the foreground's opacity.
pub fn composite(alpha: Tensor<3>, foreground: Tensor<4>, background: Tensor<4>) -> Tensor<4> {
    let a = alpha.unsqueeze_dim::<4>(3);
    a.clone() * foreground + a.neg().add_scalar(1.0) * background
}

/// The kept sky Gaussians as the rasteriser takes them.
pub fn sky_splats(sky: &SkyGaussians) -> GaussianTensors {
    GaussianTensors {
        means: sky.means.clone(),
        quats_wxyz: sky.quats.clone(),
        scales: sky.scales.clone(),
        opacities: OpacityTensor::Shared(sky.opacities.clone()),
        colors: sky.colors.clone(),
    }
}

/// Cameras as the rasteriser takes them: world-to-camera `[V, 4, 4]` and pinhole `K` `[V, 3, 3]`.
pub fn camera_tensors(cameras: &[PosedCamera], size: ImageSize, device: &Device) -> Result<CameraTensors, SceneError> {
    let pairs: Vec<(CameraFromWorld, PinholeIntrinsics)> =
        cameras.iter().map(|c| (c.world_from_camera.inverse(), c.intrinsics)).collect();
    let views = pairs.len();
    let viewmats: Vec<f32> = pairs.iter().flat_map(|(c, _)| c.to_rows()).flatten().map(|v| v as f32).collect();
    let intrinsics: Vec<f32> = pairs.iter().flat_map(|(_, k)| k.to_rows_f32()).flatten().collect();
    if viewmats.iter().chain(&intrinsics).any(|v| !v.is_finite()) {
        return Err(SceneError::NonFiniteCamera);
    }
    Ok(CameraTensors {
        world_to_camera: Tensor::from_data(TensorData::new(viewmats, [views, 4, 4]), device),
        intrinsics: Tensor::from_data(TensorData::new(intrinsics, [views, 3, 3]), device),
        size,
    })
}
