//! Rendering burn tensors: typed inputs whose names carry the conventions (world-to-camera extrinsics, `w x y z`
//! quaternions, linear scales), shape checks that report a [`SplatError`] before anything is dispatched, and
//! differentiable outputs when the tensors live on an autodiff device.

use burn::backend::Dispatch;
use burn::tensor::{DType, Int, Tensor};
use dggt_geom::ImageSize;

use crate::cull::CullStats;
use crate::error::SplatError;
use crate::op::{SplatInputs, SplatOps};
use crate::settings::{DepthStatistic, RasterSettings};
use crate::view::ViewBatch;

/// Opacities in `[0, 1]`, shared by all views or one row per view (DGGT's lifespan fades Gaussians with the
/// time of the rendered view).
#[derive(Debug, Clone)]
pub enum OpacityTensor {
    /// `[N]`.
    Shared(Tensor<1>),
    /// `[V, N]`: view `v` uses row `v`.
    PerView(Tensor<2>),
}

/// `N` Gaussians in world space, `f32` tensors on one device.
#[derive(Debug, Clone)]
pub struct GaussianTensors {
    /// `[N, 3]` centres, world coordinates.
    pub means: Tensor<2>,
    /// `[N, 4]` rotations, scalar first; any non-zero norm (normalised inside).
    pub quats_wxyz: Tensor<2>,
    /// `[N, 3]` standard deviations along the rotated axes: linear, not log.
    pub scales: Tensor<2>,
    pub opacities: OpacityTensor,
    /// `[N, K]` colours, `K >= 1` channels composited alike.
    pub colors: Tensor<2>,
}

/// `V` pinhole cameras rendered at one image size (OpenCV axes: x right, y down, z forward).
#[derive(Debug, Clone)]
pub struct CameraTensors {
    /// `[V, 4, 4]` row-major `p_cam = R p_world + t`, last row `[0, 0, 0, 1]`.
    pub world_to_camera: Tensor<3>,
    /// `[V, 3, 3]` row-major `[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` in pixels (skew ignored).
    pub intrinsics: Tensor<3>,
    pub size: ImageSize,
}

/// How to render: the host settings (whose `background` must stay `None`) and the background as a tensor.
#[derive(Debug, Clone, Default)]
pub struct RenderSettings {
    pub raster: RasterSettings,
    /// `[K]`, differentiable; `None` is black.
    pub background: Option<Tensor<1>>,
}

/// Rendered images; the meanings are those of [`Images`](crate::Images).
#[derive(Debug, Clone)]
pub struct RenderTensors {
    /// `[V, H, W, K]` composited colours plus `T_final · background`.
    pub colors: Tensor<4>,
    /// `[V, H, W]` `1 - T_final`.
    pub alpha: Tensor<3>,
    /// `[V, H, W]` camera-space depth (0 where nothing is drawn): expected, or the median as the settings say
    /// (detached: no gradient flows through a median depth).
    pub depth: Tensor<3>,
}

/// Renders every Gaussian into every camera in one call.
///
/// Gradients (on an autodiff device) reach the means, quaternions, scales, opacities, colours and background;
/// the cameras are constants. Shapes, element types, settings and camera values are checked here and reported
/// as a [`SplatError`].
pub fn render(
    gaussians: &GaussianTensors,
    cameras: &CameraTensors,
    settings: &RenderSettings,
) -> Result<RenderTensors, SplatError> {
    Ok(dispatch(gaussians, cameras, settings)?.0)
}

/// [`render`], also returning each view's [`CullStats`]. Reading them waits for the backend.
pub fn render_with_stats(
    gaussians: &GaussianTensors,
    cameras: &CameraTensors,
    settings: &RenderSettings,
) -> Result<(RenderTensors, Vec<CullStats>), SplatError> {
    let (images, stats) = dispatch(gaussians, cameras, settings)?;
    let counts = stats.into_data().try_into_vec_as::<i64>().expect("statistics are integers");
    let stats = counts
        .chunks_exact(CullStats::COUNTS)
        .map(|row| CullStats::from_counts(std::array::from_fn(|k| row[k] as usize)))
        .collect();
    Ok((images, stats))
}

fn dispatch(
    gaussians: &GaussianTensors,
    cameras: &CameraTensors,
    settings: &RenderSettings,
) -> Result<(RenderTensors, Tensor<2, Int>), SplatError> {
    let channels = check(gaussians, cameras, settings)?;
    let background = match &settings.background {
        Some(background) => background.clone(),
        None => Tensor::zeros([channels], &gaussians.means.device()),
    };
    let opacities = match &gaussians.opacities {
        OpacityTensor::Shared(values) => values.clone().into_dispatch(),
        OpacityTensor::PerView(values) => values.clone().into_dispatch(),
    };
    let inputs = SplatInputs {
        means: gaussians.means.clone().into_dispatch(),
        quats: gaussians.quats_wxyz.clone().into_dispatch(),
        scales: gaussians.scales.clone().into_dispatch(),
        opacities,
        colors: gaussians.colors.clone().into_dispatch(),
        background: background.into_dispatch(),
        viewmats: cameras.world_to_camera.clone().into_dispatch(),
        intrinsics: cameras.intrinsics.clone().into_dispatch(),
    };
    let (images, stats) = <Dispatch as SplatOps>::splat_render(inputs, settings.raster.clone(), cameras.size);
    let images = Tensor::<4>::from_dispatch(images);
    let images = RenderTensors {
        colors: images.clone().narrow(3, 0, channels),
        alpha: images.clone().narrow(3, channels, 1).squeeze_dim(3),
        depth: match settings.raster.depth {
            DepthStatistic::Expected => images.narrow(3, channels + 1, 1).squeeze_dim(3),
            DepthStatistic::Median => images.narrow(3, channels + 1, 1).squeeze_dim(3).detach(),
        },
    };
    Ok((images, Tensor::from_dispatch(stats)))
}

/// Checks shapes, element types and settings; returns the number of colour channels `K`.
fn check(gaussians: &GaussianTensors, cameras: &CameraTensors, settings: &RenderSettings) -> Result<usize, SplatError> {
    let [count, _] = gaussians.means.dims();
    let [_, channels] = gaussians.colors.dims();
    let [views, _, _] = cameras.world_to_camera.dims();
    let shape = |tensor, expected: String, actual: &[usize], wanted: &[usize]| {
        if actual == wanted {
            Ok(())
        } else {
            Err(SplatError::TensorShape { tensor, expected, actual: actual.to_vec() })
        }
    };
    shape("means", format!("[N, 3] with N = {count}"), &gaussians.means.dims(), &[count, 3])?;
    shape("quats_wxyz", format!("[N, 4] with N = {count}"), &gaussians.quats_wxyz.dims(), &[count, 4])?;
    shape("scales", format!("[N, 3] with N = {count}"), &gaussians.scales.dims(), &[count, 3])?;
    shape("colors", format!("[N, K] with N = {count}, K >= 1"), &gaussians.colors.dims(), &[count, channels.max(1)])?;
    match &gaussians.opacities {
        OpacityTensor::Shared(values) => shape("opacities", format!("[N] with N = {count}"), &values.dims(), &[count]),
        OpacityTensor::PerView(values) => {
            shape("opacities", format!("[V, N] with V = {views}, N = {count}"), &values.dims(), &[views, count])
        }
    }?;
    if let Some(background) = &settings.background {
        shape("background", format!("[K] with K = {channels}"), &background.dims(), &[channels])?;
    }
    shape("world_to_camera", format!("[V, 4, 4] with V = {views}"), &cameras.world_to_camera.dims(), &[views, 4, 4])?;
    shape("intrinsics", format!("[V, 3, 3] with V = {views}"), &cameras.intrinsics.dims(), &[views, 3, 3])?;

    let opacities_dtype = match &gaussians.opacities {
        OpacityTensor::Shared(values) => values.dtype(),
        OpacityTensor::PerView(values) => values.dtype(),
    };
    let dtypes = [
        ("means", gaussians.means.dtype()),
        ("quats_wxyz", gaussians.quats_wxyz.dtype()),
        ("scales", gaussians.scales.dtype()),
        ("opacities", opacities_dtype),
        ("colors", gaussians.colors.dtype()),
        ("world_to_camera", cameras.world_to_camera.dtype()),
        ("intrinsics", cameras.intrinsics.dtype()),
    ];
    let background_dtype = settings.background.as_ref().map(|b| ("background", b.dtype()));
    for (tensor, dtype) in dtypes.into_iter().chain(background_dtype) {
        if dtype != DType::F32 {
            return Err(SplatError::ElementType { tensor, actual: format!("{dtype:?}") });
        }
    }

    if settings.raster.background.is_some() {
        return Err(SplatError::InvalidSettings {
            detail: "set the background as the `RenderSettings::background` tensor, not in `raster`".into(),
        });
    }
    settings.raster.validate(channels)?;
    check_camera_values(cameras)?;
    Ok(channels)
}

/// Camera values are checked on the host, so that a non-finite or non-positive focal length or a malformed view
/// matrix is an error rather than a failure inside the backend. Cameras are `25 V` numbers: reading them back is
/// one small transfer per call, not one per view.
fn check_camera_values(cameras: &CameraTensors) -> Result<(), SplatError> {
    let read = |tensor: &Tensor<3>, name: &'static str| {
        tensor
            .clone()
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| SplatError::ElementType { tensor: name, actual: format!("{e:?}") })
    };
    let viewmats = read(&cameras.world_to_camera, "world_to_camera")?;
    let intrinsics = read(&cameras.intrinsics, "intrinsics")?;
    ViewBatch::from_matrices(&viewmats, &intrinsics, cameras.size).map(|_| ())
}
