//! The inference path, once: every tool that runs the network (training, reconstruction, evaluation,
//! benchmarks, the stress suite) goes through it.
//!
//! In data-flow order:
//!
//! 1. [`network`]: a network from any checkpoint users have (this project's runs, whose folders
//!    `dggt-checkpoint` reads; the release's `.pt`, VGGT-1B, whose cover of the network [`coverage`] checks) with
//!    its configuration ([`settings`]: the `[model]` and `[render]` sections of a training configuration), or a
//!    fresh one;
//! 2. [`inputs`]: the views of an image folder, glob or scene export, preprocessed to the network's size;
//! 3. [`forward`]: the forward pass, dense heads a few frames at a time;
//! 4. [`cameras`]: the input views' cameras, predicted or given;
//! 5. [`scene`]: the 4D scene of the prediction ([`dggt_scene::Scene4d`]: pixel and sky Gaussians, renders at any
//!    time).
//!
//! Parity with the release's reference vectors (`dggt parity`) is `dggt-parity`'s.
//!
//! Conventions: poses world-from-camera, OpenCV axes, the world the first input view's camera frame when
//! cameras are predicted; images RGB in `[0, 1]`; scene time as [`dggt_scene::Timeline`] maps frames.

pub mod cameras;
pub mod coverage;
mod error;
pub mod forward;
pub mod inputs;
pub mod network;
pub mod scene;
pub mod settings;

pub use cameras::{InputCameras, ViewSlot, decode_cameras, input_views};
pub use error::InferError;
pub use forward::{MotionPath, Prediction, forward_chunked, heads_chunked, is_still};
pub use inputs::{GroundTruth, InputImage, InputSet};
pub use network::{
    Architecture, CheckpointInfo, DEFAULT_PRESET, LoadedNetwork, StartingWeights, fresh_model, load_network,
};
pub use scene::{SceneOptions, SkyChoice};
pub use settings::{CameraSource, ModelSection, RenderSection, TrainedSettings};
