//! One training sample as tensors: the input images for the network, and per view the ground truth the losses
//! compare with (image, masks, the export's camera, depth where the export has it).
//!
//! Ground-truth cameras are re-expressed in the frame of the first input view (`world' = camera of input 0`),
//! the frame the camera head predicts in, so they can stand in for predicted cameras and supervise them.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::{DepthFlowMap, LoadedSample, PreparedView, Preprocess, Scene};
use dggt_geom::{ImageSize, PosedCamera, WorldFromCamera};
use dggt_scene::Timeline;

use crate::error::TrainError;

/// One view's ground truth.
#[derive(Debug, Clone)]
pub struct ViewTruth {
    /// Position in the scene's frame list.
    pub frame: usize,
    pub rig_camera: usize,
    /// Scene time on the sample's [`Timeline`].
    pub time: f64,
    /// The export's camera, in the first input view's frame.
    pub camera: PosedCamera,
    /// `[H, W, 3]` RGB in `[0, 1]`.
    pub image: Tensor<3>,
    /// `[H, W]` 1 where sky.
    pub sky: Option<Tensor<2>>,
    /// `[H, W]` 1 where dynamic.
    pub dynamic: Option<Tensor<2>>,
    /// Pixels (row-major indices of the preprocessed image) with a measured depth, and the depths.
    pub depth: Option<(Vec<i64>, Vec<f32>)>,
}

/// A sample ready for a training step.
#[derive(Debug, Clone)]
pub struct StepBatch {
    pub step: u64,
    /// `[1, S, 3, H, W]` the network's input.
    pub images: Tensor<5>,
    pub size: ImageSize,
    pub timeline: Timeline,
    pub inputs: Vec<ViewTruth>,
    pub targets: Vec<ViewTruth>,
}

impl StepBatch {
    /// Moves a decoded sample to `device`. `with_depth` reads the export's depth maps of the input views.
    pub fn new(
        sample: &LoadedSample,
        scene: &Scene,
        preprocess: &Preprocess,
        with_depth: bool,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let first = sample.inputs.first().ok_or_else(|| TrainError::Invalid {
            what: format!("sample of step {}", sample.step),
            detail: "no input views".into(),
        })?;
        let size = first.image.size;
        if let Some(view) = sample.inputs.iter().chain(&sample.targets).find(|v| v.image.size != size) {
            return Err(TrainError::Invalid {
                what: format!("view (frame {}, camera {})", view.frame, view.camera),
                detail: format!("size {} differs from the first input's {size}", view.image.size),
            });
        }
        let timeline = Timeline::new(&sample.sample.input_frames)?;
        let reference = first.world_from_camera;
        let truth = |view: &PreparedView, depth: bool| -> Result<ViewTruth, TrainError> {
            Ok(ViewTruth {
                frame: view.frame,
                rig_camera: view.camera,
                time: timeline.time(view.frame as f64),
                camera: PosedCamera {
                    world_from_camera: relative_pose(&reference, &view.world_from_camera),
                    intrinsics: view.intrinsics,
                },
                image: hwc_image(view, device),
                sky: view.sky_mask.as_ref().map(|m| mask_tensor(&m.data, size, device)),
                dynamic: view.dynamic_mask.as_ref().map(|m| mask_tensor(&m.data, size, device)),
                depth: if depth { depth_samples(scene, preprocess, view)? } else { None },
            })
        };
        let inputs = sample.inputs.iter().map(|v| truth(v, with_depth)).collect::<Result<Vec<_>, _>>()?;
        let targets = sample.targets.iter().map(|v| truth(v, false)).collect::<Result<Vec<_>, _>>()?;
        let (h, w) = (size.height as usize, size.width as usize);
        let planar: Vec<f32> = sample.inputs.iter().flat_map(|v| v.image.data.iter().copied()).collect();
        let images = Tensor::from_data(TensorData::new(planar, [1, sample.inputs.len(), 3, h, w]), device);
        Ok(Self { step: sample.step, images, size, timeline, inputs, targets })
    }
}

/// `view` expressed in the frame of `reference`: `reference⁻¹ · view`.
pub fn relative_pose(reference: &WorldFromCamera, view: &WorldFromCamera) -> WorldFromCamera {
    (reference.inverse() * *view).relabel()
}

fn hwc_image(view: &PreparedView, device: &Device) -> Tensor<3> {
    let (h, w) = (view.image.size.height as usize, view.image.size.width as usize);
    Tensor::<3>::from_data(TensorData::new(view.image.data.clone(), [3, h, w]), device).permute([1, 2, 0])
}

fn mask_tensor(mask: &[u8], size: ImageSize, device: &Device) -> Tensor<2> {
    let values: Vec<f32> = mask.iter().map(|&m| if m > 0 { 1.0 } else { 0.0 }).collect();
    Tensor::from_data(TensorData::new(values, [size.height as usize, size.width as usize]), device)
}

/// The export's quarter-resolution depth of `view`, mapped to pixels of the preprocessed image: a cell's
/// centre `(4 col + 2, 4 row + 2)` (continuous coordinates of the original image) lands at the scaled position
/// less the rows cropped from the top. `None` when the export has no depth for the view.
fn depth_samples(
    scene: &Scene,
    preprocess: &Preprocess,
    view: &PreparedView,
) -> Result<Option<(Vec<i64>, Vec<f32>)>, TrainError> {
    let Some(path) = &scene.view(view.frame, view.camera).files.depth_flow else { return Ok(None) };
    let original = scene.cameras[view.camera].size;
    let map = DepthFlowMap::read(path, original)?;
    let plan = preprocess.plan(original)?;
    let sx = plan.resized.width as f64 / original.width as f64;
    let sy = plan.resized.height as f64 / original.height as f64;
    let (w, h) = (plan.output.width as i64, plan.output.height as i64);
    let (mut pixels, mut depths) = (Vec::new(), Vec::new());
    for (i, &d) in map.depth.iter().enumerate() {
        if !(d > 0.0) {
            continue;
        }
        let (row, col) = ((i / map.size.width as usize) as f64, (i % map.size.width as usize) as f64);
        let x = ((4.0 * col + 2.0) * sx).floor() as i64;
        let y = ((4.0 * row + 2.0) * sy - plan.crop_top as f64).floor() as i64;
        if (0..w).contains(&x) && (0..h).contains(&y) {
            pixels.push(y * w + x);
            depths.push(d);
        }
    }
    Ok(Some((pixels, depths)))
}
