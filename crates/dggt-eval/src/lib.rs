//! `dggt eval`: the evaluation protocols of DGGT over scene exports, from one checkpoint.
//!
//! - [`protocol`]: the paper's protocol (inputs at frames 0, 5, 10, 15 of a 20-frame window, reconstruction
//!   and novel-view splits) and the release's reconstruction and interpolation modes;
//! - the scores themselves (PSNR, SSIM, D-RMSE, scene flow) come from `dggt-metrics`, LPIPS-Alex from
//!   `dggt-losses`;
//! - [`grid`]: where the export's quarter-resolution lidar cells fall in the rendered view;
//! - [`motion`]: the predicted flow of the surface at an input view under each motion source, in the export's
//!   axes and units;
//! - [`sources`]: the moving objects between the inputs drawn every way the scene can draw them (held,
//!   cross-faded, by velocity, by instance, by the learnt flow), scored on the dynamic mask and cropped side by side;
//! - [`runner`]: forward pass, renders of every target view, metrics, stage times;
//! - [`report`]: per-view records, per-scene and overall means, `eval.json` and `eval.md`.

mod error;
pub mod grid;
pub mod motion;
pub mod protocol;
pub mod report;
pub mod runner;
pub mod sources;

pub use error::EvalError;
pub use motion::motion_label;
pub use protocol::{Protocol, ProtocolKind, TargetKind};
pub use report::{
    DepthParts, EvalReport, MOTION_HELD, MOTION_INSTANCES, MOTION_LEARNT, MOTION_VELOCITY, SceneReport,
    SourceFlowMetrics, SourcePsnr, SourceSummary, SplitSummary, ViewRecord,
};
pub use runner::{EvalOptions, LpipsWeights, evaluate};
pub use sources::{CropImages, ImageSource};
