//! One sample's training objective: the batch ([`batch`]: input images and each view's ground truth), the
//! network run and its scene rendered through the inference path (`dggt-infer`), and the weighted losses
//! ([`weights`], [`objective`]).
//!
//! It sits between inference and the trainer so that the trainer and the stress suite, which drives the same
//! objective through extreme inputs, share one definition of it.

pub mod batch;
mod error;
pub mod objective;
pub mod weights;

pub use batch::{DepthFlowMaps, DepthFlowSamples, MOVING_SPEED, StepBatch, ViewTruth, depth_flow_samples};
pub use error::ObjectiveError;
pub use objective::{Forward, Objective, RenderedView, SampleLoss, ViewsToRender, learnt_flow_loss};
pub use weights::{LossTerm, LossWeights};
