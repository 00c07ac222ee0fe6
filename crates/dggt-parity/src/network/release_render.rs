//! The release's inference render of one scene, as the parity vectors' `render.*` outputs hold it: the static
//! Gaussians of every frame (non-sky pixels whose dynamic logit is below 0.5), faded to each frame's time, plus
//! that frame's dynamic Gaussians (all its non-sky pixels), rasterised at the frame's camera; the sky Gaussians
//! rasterised in every view and min-max normalised; and the foreground composited over the sky.
//!
//! Gaussians are one per pixel: means from the unprojected depth, rotations as `w x y z`, linear scales,
//! post-sigmoid colours. Everything after the masks is a tensor expression, so gradients reach the maps. The
//! compositing is `dggt-scene`'s ([`composite`]); only the sky's normalisation is the release's own.

use std::fmt;

use burn::tensor::{Int, Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics, PosedCamera};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_model::lifespan::{dynamic_opacity, frame_times, opacity_at, static_opacity};
use dggt_model::sky::SkyGaussians;
use dggt_scene::{camera_tensors, composite, sky_splats};
use dggt_splat::{CameraTensors, GaussianTensors, OpacityTensor, RenderSettings, RenderTensors, SplatError, render};

/// Added to the sky's range in the min-max normalisation.
const MINMAX_EPS: f32 = 1e-8;

/// Why the scene could not be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    #[error("a scene is one batch element; the maps hold {0}")]
    NotOneScene(usize),
    #[error("{frames} frames need as many cameras and sky flags; there are {cameras} cameras and {flags} sky flags")]
    FrameCount { frames: usize, cameras: usize, flags: usize },
    #[error("reading the dynamic logits back: {0}")]
    Readback(String),
    /// The cameras as the rasteriser takes them could not be made.
    #[error("the rasteriser's cameras: {0}")]
    Cameras(String),
    #[error("rendering {target}: {source}")]
    Rasterising { target: RenderTarget, source: SplatError },
}

/// What a render was of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderTarget {
    /// The foreground Gaussians at this frame's camera.
    Frame(usize),
    /// The sky Gaussians in every view.
    Sky,
}

impl fmt::Display for RenderTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RenderTarget::Frame(frame) => write!(f, "frame {frame}"),
            RenderTarget::Sky => f.write_str("the sky"),
        }
    }
}

/// One scene's per-pixel Gaussians and what it is rendered with (batch of one).
pub struct SceneInputs<'a> {
    pub maps: &'a GaussianMaps,
    /// `[1, S, H, W]` dynamic logits.
    pub dynamic_logit: Tensor<4>,
    /// `[1, S, H, W, 3]` world-space means.
    pub means: Tensor<5>,
    /// `S·H·W` flags, row-major: the pixel is not sky.
    pub non_sky: &'a [bool],
    /// Each frame's camera.
    pub cameras: &'a [(CameraFromWorld, PinholeIntrinsics)],
    pub sky: &'a SkyGaussians,
}

/// The rendered scene and its intermediate values.
pub struct SceneRender {
    /// `S·H·W` flags: the pixel's Gaussian is static.
    pub static_mask: Vec<bool>,
    /// `[N_static]` static opacities, in `static_mask` order.
    pub static_opacity: Tensor<1>,
    /// Per frame, `[N_static]` static opacities faded to the frame's time.
    pub static_opacity_at_frame: Vec<Tensor<1>>,
    /// Static and dynamic Gaussians, per frame: colours `[S, H, W, 3]`, alpha and expected depth `[S, H, W]`.
    pub foreground: RenderTensors,
    /// `[S, H, W, 3]` the sky Gaussians rendered in every view.
    pub sky: Tensor<4>,
    /// `[S, H, W, 3]` `sky` min-max normalised over the whole tensor.
    pub sky_minmax: Tensor<4>,
    /// `[S, H, W, 3]` `alpha · foreground + (1 - alpha) · sky_minmax`.
    pub final_rgb: Tensor<4>,
}

/// The release's inference static mask: not sky and a dynamic logit below 0.5.
pub fn static_mask(non_sky: &[bool], dynamic_logit: &[f32]) -> Vec<bool> {
    // The release compares the raw logit, not its sigmoid, with 0.5.
    non_sky.iter().zip(dynamic_logit).map(|(&non_sky, &logit)| non_sky && logit < 0.5).collect()
}

/// Renders the scene at every frame's camera.
pub fn render_scene(inputs: &SceneInputs<'_>, size: ImageSize) -> Result<SceneRender, RenderError> {
    let maps = inputs.maps;
    let [batch, frames, height, width] = maps.opacity.dims();
    if batch != 1 {
        return Err(RenderError::NotOneScene(batch));
    }
    if inputs.cameras.len() != frames || inputs.non_sky.len() != frames * height * width {
        let (cameras, flags) = (inputs.cameras.len(), inputs.non_sky.len());
        return Err(RenderError::FrameCount { frames, cameras, flags });
    }
    let device = maps.opacity.device();
    let pixels = height * width;
    let count = frames * pixels;
    let logits = inputs
        .dynamic_logit
        .clone()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| RenderError::Readback(format!("{e:?}")))?;
    let mask = static_mask(inputs.non_sky, &logits);
    let index: Vec<i64> = (0..count).filter(|&i| mask[i]).map(|i| i as i64).collect();
    let statics = Tensor::<1, Int>::from_data(TensorData::new(index.clone(), [index.len()]), &device);

    let flat = |tensor: Tensor<5>, channels: usize| tensor.reshape([count, channels]);
    let rows = |tensor: Tensor<4>| tensor.reshape([count]);
    let (means, quats) = (flat(inputs.means.clone(), 3), flat(maps.rotation.clone(), 4));
    let (scales, colors) = (flat(maps.scale.clone(), 3), flat(maps.rgb.clone(), 3));
    let (opacity, logit) = (rows(maps.opacity.clone()), rows(inputs.dynamic_logit.clone()));

    let times = frame_times(frames);
    let source_times: Vec<f32> = index.iter().map(|&i| times[i as usize / pixels] as f32).collect();
    let source_times = Tensor::<1>::from_data(TensorData::new(source_times, [index.len()]), &device);
    let opacity_static = static_opacity(opacity.clone(), logit.clone()).select(0, statics.clone());
    let lifespan_static = rows(maps.lifespan.clone()).select(0, statics.clone());
    let opacity_dynamic = dynamic_opacity(opacity, logit);
    let static_opacity_at_frame: Vec<Tensor<1>> = times
        .iter()
        .map(|&t| opacity_at(opacity_static.clone(), lifespan_static.clone(), source_times.clone(), t))
        .collect();

    let settings = RenderSettings::default();
    let mut renders = Vec::with_capacity(frames);
    for (frame, at_frame) in static_opacity_at_frame.iter().enumerate() {
        // The frame's dynamic Gaussians: all its non-sky pixels, static ones included.
        let own: Vec<i64> =
            (frame * pixels..(frame + 1) * pixels).filter(|&i| inputs.non_sky[i]).map(|i| i as i64).collect();
        let own = Tensor::<1, Int>::from_data(TensorData::new(own.clone(), [own.len()]), &device);
        let pick = |tensor: &Tensor<2>| {
            Tensor::cat(vec![tensor.clone().select(0, statics.clone()), tensor.clone().select(0, own.clone())], 0)
        };
        let gaussians = GaussianTensors {
            means: pick(&means),
            quats_wxyz: pick(&quats),
            scales: pick(&scales),
            opacities: OpacityTensor::Shared(Tensor::cat(
                vec![at_frame.clone(), opacity_dynamic.clone().select(0, own.clone())],
                0,
            )),
            colors: pick(&colors),
        };
        let cameras = cameras_of(&inputs.cameras[frame..=frame], size, &device)?;
        let rasterising = |source| RenderError::Rasterising { target: RenderTarget::Frame(frame), source };
        renders.push(render(&gaussians, &cameras, &settings).map_err(rasterising)?);
    }
    let foreground = RenderTensors {
        colors: Tensor::cat(renders.iter().map(|r| r.colors.clone()).collect(), 0),
        alpha: Tensor::cat(renders.iter().map(|r| r.alpha.clone()).collect(), 0),
        depth: Tensor::cat(renders.iter().map(|r| r.depth.clone()).collect(), 0),
    };

    let sky_gaussians = sky_splats(inputs.sky);
    let cameras = cameras_of(inputs.cameras, size, &device)?;
    let rasterising = |source| RenderError::Rasterising { target: RenderTarget::Sky, source };
    let sky_raw = render(&sky_gaussians, &cameras, &settings).map_err(rasterising)?.colors;
    // Inference only: one min and max over every frame and channel.
    let low = sky_raw.clone().min().reshape([1, 1, 1, 1]);
    let high = sky_raw.clone().max().reshape([1, 1, 1, 1]);
    let sky_minmax = (sky_raw.clone() - low.clone()) / (high - low).add_scalar(MINMAX_EPS);
    let final_rgb = composite(foreground.alpha.clone(), foreground.colors.clone(), sky_minmax.clone());

    Ok(SceneRender {
        static_mask: mask,
        static_opacity: opacity_static,
        static_opacity_at_frame,
        foreground,
        sky: sky_raw,
        sky_minmax,
        final_rgb,
    })
}

/// The cameras as the rasteriser takes them.
fn cameras_of(
    cameras: &[(CameraFromWorld, PinholeIntrinsics)],
    size: ImageSize,
    device: &burn::tensor::Device,
) -> Result<CameraTensors, RenderError> {
    let posed: Vec<PosedCamera> = cameras
        .iter()
        .map(|(camera_from_world, intrinsics)| PosedCamera {
            world_from_camera: camera_from_world.inverse(),
            intrinsics: *intrinsics,
        })
        .collect();
    camera_tensors(&posed, size, device).map_err(|e| RenderError::Cameras(e.to_string()))
}
