//! `dggt eval`: the evaluation protocols of DGGT over scene exports, from one checkpoint.
//!
//! - [`protocol`]: the paper's protocol (inputs at frames 0, 5, 10, 15 of a 20-frame window, reconstruction
//!   and novel-view splits) and the release's reconstruction and interpolation modes;
//! - [`metrics`]: D-RMSE after scale-and-shift alignment and STORM's scene-flow metrics, as pure functions
//!   (PSNR, SSIM and LPIPS-Alex come from `dggt-losses`);
//! - [`grid`]: where the export's quarter-resolution lidar cells fall in the rendered view;
//! - [`runner`]: forward pass, renders of every target view, metrics, stage times;
//! - [`report`]: per-view records, per-scene and overall means, `eval.json` and `eval.md`.

mod error;
pub mod grid;
pub mod metrics;
pub mod protocol;
pub mod report;
pub mod runner;

pub use error::EvalError;
pub use metrics::{DepthAlignment, FlowMetrics, MetricError, aligned_depth_rmse, scene_flow_metrics};
pub use protocol::{Protocol, ProtocolKind, Split};
pub use report::{EvalReport, MOTION_HELD, SceneReport, SplitSummary, ViewRecord};
pub use runner::{EvalOptions, LpipsWeights, MotionSource, evaluate};
