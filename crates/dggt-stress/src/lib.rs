//! The numerical stress suite: drives the pipeline through what breaks numerics and reports every non-finite
//! value by stage (geometry, network, Gaussians, render, losses, gradients).
//!
//! Three groups of cases ([`run_suite`]):
//! - geometry: SLERP between near-identical and opposite rotations, huge translations, one-frame and
//!   huge-index timelines, extreme pose encodings;
//! - crafted: hand-made head outputs at the extremes (opacities 0 and 1, lifespans near 0 and huge, degenerate,
//!   huge and anisotropic scales, zero quaternions, depths 0 and 1e6, empty and all-dynamic frames, all-sky and
//!   no-sky views, moderate and huge motion-head velocities, random mixtures of all of them) through placement,
//!   rendering, every loss and the backward pass; non-finite depths and velocities must be rejected with an
//!   error;
//! - network: the tiny architecture on black, white and grey images, all-sky and sky-free masks, one and 64
//!   input frames, with its own predicted cameras, through to every parameter's gradient; again with the
//!   network computing and training in f16 and in bf16 (listed as skipped where the device lacks the type).
//!
//! `dggt stress` runs it (`--scope full` for the larger version, `--scope device` for what a GPU adds to the
//! CPU suite); the `stress_suite` test runs the bounded scope on the CPU and the device scope on wgpu.

mod crafted;
mod error;
mod geometry;
mod network;
mod pipeline;
pub mod probe;
mod scenario;
pub mod suite;

pub use error::StressError;
pub use probe::{Finding, Probe, Stage};
pub use suite::{CaseOutcome, Expect, StressOptions, StressReport, StressScope, run_suite};
