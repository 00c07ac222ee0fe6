//! [Rerun](https://rerun.io) recordings of the project's results, to be scrubbed through in rerun's viewer: a
//! training run live (its losses, and at each validation pass its renders, cameras and Gaussians, on a `step`
//! time line: [`training`]), and a reconstruction (`.rrd`): each input camera's pose and pinhole, its image, depth, dynamic and sky masks; the static and
//! sky Gaussians once and the dynamic ones at every rendered time as 3D Gaussian splats; the renders; the moving
//! objects' boxes and trajectories; the summary's figures.
//!
//! The recording is made from a `dggt reconstruct` output folder (its files are the interface: what the
//! recording shows is what the folder holds), streamed to the file one file at a time, so that memory stays
//! bounded by the largest single file.
//!
//! - [`reconstruction`]: the folder read and logged ([`record_reconstruction`]);
//! - [`splats`]: Gaussians in rerun's natural form (linear scales, RGBA colours with the opacity);
//! - [`components`]: cameras, images and depth as rerun components;
//! - [`live`]: a recording written while a run goes, which never makes the run wait;
//! - [`training`]: a DGGT run shown live ([`TrainingRecording`], `dggt train --rerun`), from what the trainer
//!   hands its watcher; [`refiner`]: the same for the refiner's training ([`RefinerRecording`]).
//!
//! Conventions in the recording: the world is the reconstruction's (the first input camera's frame, OpenCV axes:
//! x right, y down, z forward, declared on `world`); each camera entity carries its world-from-camera transform
//! and a pinhole in pixels with OpenCV camera axes; two time lines, `time` (seconds since the first chosen frame)
//! and `frame` (the source log's frame number, 10 Hz).

pub mod components;
mod error;
pub mod live;
pub mod reconstruction;
pub mod refiner;
pub mod splats;
pub mod training;

pub use error::RerunError;
pub use live::{Destination, LiveReport};
pub use reconstruction::{RecordingReport, record_reconstruction};
pub use refiner::RefinerRecording;
pub use training::TrainingRecording;
