//! The scores of a rendered view against the truth, computed on the host in `f64` (not differentiable: the
//! training losses are `dggt-losses`). One crate for the trainer's validation, the evaluation and the
//! benchmarks, so that every figure the project reports is computed by the same function.
//!
//! * [`image`]: PSNR and SSIM as scikit-image computes them.
//! * [`depth`]: D-RMSE after the least-squares scale and shift.
//! * [`motion`]: EPE3D, Acc5, Acc10 and the angular error of 3D scene flow.
//! * [`sampling`]: a map read at continuous coordinates (the pixel there, or bilinearly), and the mean of present
//!   values.
//!
//! Every function rejects inputs it cannot score (no values, mismatched lengths, non-finite values, images
//! too small for the SSIM window) with a [`MetricError`] rather than returning NaN.

pub mod depth;
pub mod error;
pub mod image;
pub mod motion;
pub mod sampling;

pub use depth::{DepthAlignment, aligned_depth_rmse};
pub use error::MetricError;
pub use image::{ImageMetrics, ImageShape, Ssim, image_metrics, masked_psnr, psnr, ssim, ssim_map};
pub use motion::{FlowMetrics, scene_flow_metrics};
pub use sampling::{mean_present, sample_bilinear, sample_pixel};
