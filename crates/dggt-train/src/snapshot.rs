//! A validation pass's picture of its first scene, for a watcher ([`crate::watch`]): the rendered targets
//! beside their truth, the input views with the network's cameras, depths and dynamic probabilities, and the
//! window's Gaussians, copied to the host as plain data; and the 8-bit images validation writes its comparisons
//! with.
//!
//! Conventions of a snapshot: images are 8-bit RGB or grey, row-major; depths are z-depths in world units;
//! cameras are world-from-camera with OpenCV axes (x right, y down, z forward) in the world of the window, the
//! frame of its first input camera (the predicted cameras in the network's own scale, the export's in metres);
//! Gaussians carry linear scales, `w x y z` quaternions and opacity in `[0, 1]`.

use burn::tensor::activation::sigmoid;
use dggt_formats::ply::GaussianCloud;
use dggt_geom::{ImageSize, PosedCamera};
use dggt_infer::cameras::decode_cameras;
use dggt_model::host::host_f32;
use dggt_objective::{Forward, RenderedView, StepBatch};
use dggt_scene::MIN_OPACITY;
use image::{GrayImage, ImageBuffer, Pixel, RgbImage};

use crate::error::TrainError;

/// The views a validation pass pictures: `(frame, camera)` positions in its first scene.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ValidationViews {
    pub inputs: Vec<(usize, usize)>,
    pub targets: Vec<(usize, usize)>,
}

/// How a validation pass pictures its scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SnapshotOptions {
    /// At most this many Gaussians (thinned evenly); 0 keeps none.
    pub max_splats: usize,
}

/// What one validation window looked like at one step (conventions in the module's doc).
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationSnapshot {
    /// The validation scene pictured (the first).
    pub scene: String,
    pub targets: Vec<TargetSnapshot>,
    pub inputs: Vec<InputSnapshot>,
    /// The window's pixel Gaussians whose opacity reaches the rasteriser's threshold (the sky left out), thinned
    /// evenly to the snapshot's `max_splats`.
    pub gaussians: GaussianCloud,
}

/// One rendered target view.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSnapshot {
    /// Position in the scene's frames and cameras.
    pub frame: usize,
    pub camera: usize,
    pub render: RgbImage,
    pub truth: RgbImage,
    /// `4 |render - truth|`, as the validation PNGs show it.
    pub difference: RgbImage,
    /// The render's expected depth (0 where nothing was drawn).
    pub depth: DepthMap,
}

/// One input view: where the network placed its camera and where the export has it, what it saw and what
/// the network made of it.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSnapshot {
    pub frame: usize,
    pub camera: usize,
    /// Scene time of the view.
    pub time: f64,
    pub predicted: PosedCamera,
    pub export: PosedCamera,
    pub image: RgbImage,
    /// The network's depth.
    pub depth: DepthMap,
    /// The network's dynamic probability as grey levels; `None` without a dynamic head.
    pub dynamic: Option<GrayImage>,
}

/// A depth image in world units.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    pub size: ImageSize,
    /// Row-major.
    pub depths: Vec<f32>,
}

impl ValidationSnapshot {
    /// The snapshot of a validation pass over `batch` whose network ran as `forward` and rendered `views`.
    pub(crate) fn new(
        scene: &str,
        forward: &Forward,
        views: &[RenderedView],
        batch: &StepBatch,
        options: SnapshotOptions,
    ) -> Result<Self, TrainError> {
        let size = batch.size;
        let mut targets = Vec::with_capacity(views.len());
        for view in views {
            let truth = &batch.targets[view.truth_index];
            let render = host_f32(view.rgb.clone(), "validation render")?;
            let truth_rgb = host_f32(truth.image.clone(), "validation truth")?;
            targets.push(TargetSnapshot {
                frame: truth.frame,
                camera: truth.rig_camera,
                render: rgb_image(size, &render, "validation render")?,
                truth: rgb_image(size, &truth_rgb, "validation truth")?,
                difference: difference_image(size, &render, &truth_rgb)?,
                depth: DepthMap { size, depths: host_f32(view.depth.clone(), "rendered depth")? },
            });
        }
        Ok(Self {
            scene: scene.to_owned(),
            targets,
            inputs: input_snapshots(forward, batch)?,
            gaussians: window_gaussians(forward, options.max_splats)?,
        })
    }
}

/// The window's pixel Gaussians whose opacity reaches the rasteriser's threshold, thinned evenly to at most
/// `max_splats`.
fn window_gaussians(forward: &Forward, max_splats: usize) -> Result<GaussianCloud, TrainError> {
    if max_splats == 0 {
        return Ok(GaussianCloud::default());
    }
    let pixels = &forward.scene.pixels;
    let opacity = host_f32(pixels.opacity.clone(), "opacity")?;
    let visible: Vec<usize> = (0..opacity.len()).filter(|&i| opacity[i] >= MIN_OPACITY).collect();
    let stride = visible.len().div_ceil(max_splats).max(1);
    let kept: Vec<usize> = visible.iter().copied().step_by(stride).collect();
    let (means, scales, colors) = (
        host_f32(pixels.means.clone(), "means")?,
        host_f32(pixels.scales.clone(), "scales")?,
        host_f32(pixels.colors.clone(), "colours")?,
    );
    let quats = host_f32(pixels.quats_wxyz.clone(), "rotations")?;
    let triple = |values: &[f32], i: usize| [values[3 * i], values[3 * i + 1], values[3 * i + 2]];
    let cloud = GaussianCloud {
        means: kept.iter().map(|&i| triple(&means, i)).collect(),
        quats_wxyz: kept.iter().map(|&i| std::array::from_fn(|k| quats[4 * i + k])).collect(),
        scales: kept.iter().map(|&i| triple(&scales, i)).collect(),
        opacities: kept.iter().map(|&i| opacity[i]).collect(),
        colors: kept.iter().map(|&i| triple(&colors, i)).collect(),
    };
    Ok(cloud)
}

/// Every input view of `batch`: the predicted camera (the camera head's last iteration), the export's, the
/// image, the network's depth and dynamic probability.
fn input_snapshots(forward: &Forward, batch: &StepBatch) -> Result<Vec<InputSnapshot>, TrainError> {
    let size = batch.size;
    let encoding = forward.encodings.last().ok_or_else(|| snapshot_error("the network returned no camera encoding"))?;
    let predicted = decode_cameras(encoding.clone(), size)?;
    let depth = host_f32(forward.depth.clone(), "depth")?;
    let dynamic = match &forward.dynamic_logit {
        Some(logit) => Some(host_f32(sigmoid(logit.clone()), "dynamic probability")?),
        None => None,
    };
    let per_view = size.width as usize * size.height as usize;
    let mut inputs = Vec::with_capacity(batch.inputs.len());
    for (s, (view, predicted)) in batch.inputs.iter().zip(predicted).enumerate() {
        let range = s * per_view..(s + 1) * per_view;
        inputs.push(InputSnapshot {
            frame: view.frame,
            camera: view.rig_camera,
            time: view.time,
            predicted,
            export: view.camera,
            image: rgb_image(size, &host_f32(view.image.clone(), "input image")?, "input image")?,
            depth: DepthMap { size, depths: depth.get(range.clone()).ok_or_else(|| too_short("depth"))?.to_vec() },
            dynamic: match &dynamic {
                Some(p) => Some(image_of(size, p.get(range).ok_or_else(|| too_short("dynamic"))?, "dynamic")?),
                None => None,
            },
        });
    }
    Ok(inputs)
}

fn byte(value: f32) -> u8 {
    (value.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// `[H, W, 3]` values in `[0, 1]` as 8-bit RGB.
pub(crate) fn rgb_image(size: ImageSize, rgb: &[f32], what: &str) -> Result<RgbImage, TrainError> {
    image_of(size, rgb, what)
}

/// `4 |a - b|` of two `[H, W, 3]` images in `[0, 1]`, as 8-bit RGB.
pub(crate) fn difference_image(size: ImageSize, a: &[f32], b: &[f32]) -> Result<RgbImage, TrainError> {
    let values: Vec<f32> = a.iter().zip(b).map(|(a, b)| 4.0 * (a - b).abs()).collect();
    image_of(size, &values, "render - truth")
}

/// Values in `[0, 1]` (clamped) as an 8-bit image of `size`; an error naming `what` when their count is not
/// the image's.
fn image_of<P: Pixel<Subpixel = u8>>(
    size: ImageSize,
    values: &[f32],
    what: &str,
) -> Result<ImageBuffer<P, Vec<u8>>, TrainError> {
    let expected = size.width as usize * size.height as usize * P::CHANNEL_COUNT as usize;
    if values.len() != expected {
        return Err(snapshot_error(format!(
            "{what}: {} values for a {}x{} image of {} channel(s)",
            values.len(),
            size.width,
            size.height,
            P::CHANNEL_COUNT
        )));
    }
    Ok(ImageBuffer::from_vec(size.width, size.height, values.iter().map(|&v| byte(v)).collect())
        .expect("as many values as the image holds (checked above)"))
}

fn too_short(what: &str) -> TrainError {
    snapshot_error(format!("{what}: fewer values than the input views hold"))
}

fn snapshot_error(detail: impl Into<String>) -> TrainError {
    TrainError::Snapshot(detail.into())
}
