//! The input views' cameras: decoded from the camera head's encodings, or given (an export's poses expressed
//! in the first input camera's frame), paired with each view's rig camera and scene time.
//!
//! Conventions: poses are world-from-camera with OpenCV axes; the world of a prediction is the first input
//! view's camera frame; intrinsics are at the network's input resolution.

use burn::tensor::Tensor;
use dggt_geom::{ImageSize, PoseEncoding, PosedCamera};
use dggt_model::host::host_f32;
use dggt_scene::InputView;

use crate::error::InferError;
use crate::forward::Prediction;

/// Predicted fields of view are clamped to this range (radians) before decoding, so an untrained camera head
/// still yields a finite camera.
pub const FOV_RANGE: (f64, f64) = (0.05, 3.0);

/// Where the cameras that place the input views' Gaussians come from.
#[derive(Debug, Clone, PartialEq)]
pub enum InputCameras {
    /// The camera head's final encoding, decoded ([`decode_cameras`]).
    Predicted,
    /// One camera per input view, in view order.
    Given(Vec<PosedCamera>),
}

/// Which rig camera took an input view, and when (scene time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSlot {
    pub rig_camera: usize,
    pub time: f64,
}

/// The input views of `prediction` with their cameras.
pub fn input_views(
    prediction: &Prediction,
    slots: &[ViewSlot],
    cameras: InputCameras,
    size: ImageSize,
) -> Result<Vec<InputView>, InferError> {
    let cameras = match cameras {
        InputCameras::Predicted => decode_cameras(prediction.pose_encoding(), size)?,
        InputCameras::Given(cameras) => cameras,
    };
    if cameras.len() != slots.len() {
        return Err(InferError::CameraCount { cameras: cameras.len(), views: slots.len() });
    }
    Ok(slots
        .iter()
        .zip(cameras)
        .map(|(slot, camera)| InputView { rig_camera: slot.rig_camera, time: slot.time, camera })
        .collect())
}

/// Decodes `[1, S, 9]` encodings to cameras (fields of view clamped to [`FOV_RANGE`]).
pub fn decode_cameras(encoding: Tensor<3>, size: ImageSize) -> Result<Vec<PosedCamera>, InferError> {
    let values = host_f32(encoding, "pose encodings")?;
    values
        .chunks_exact(9)
        .map(|v| {
            let mut array: [f64; 9] = std::array::from_fn(|i| v[i] as f64);
            for fov in &mut array[7..9] {
                *fov = fov.clamp(FOV_RANGE.0, FOV_RANGE.1);
            }
            let (camera_from_world, intrinsics) = PoseEncoding::from_array(array).decode(size)?;
            Ok(PosedCamera { world_from_camera: camera_from_world.inverse(), intrinsics })
        })
        .collect()
}
