//! Driving-scene data for dggt: everything between files on disk and the tensors a training step consumes.
//!
//! - [`layout`]: file names of the scene-export layout (drivestudio / OmniRe); [`variant`]: what its Waymo,
//!   nuScenes, Argoverse 2 and STORM variants put there, and how to tell them apart.
//! - [`export`], [`kitti`], [`lidar`], [`depth_flow`]: readers of the driving-log formats into a [`Scene`].
//! - [`scene`]: the in-memory log: cameras, frames, ground-truth poses, per-view files.
//! - [`preprocess`]: the release's resize/crop of images and masks, with intrinsics to match;
//!   [`views`] applies it to one view of a scene.
//! - [`index`]: the scenes of a run's datasets, found and checked once and cached; [`mix`]: which scene each
//!   training step draws.
//! - [`sampler`]: which input and target frames each training step sees, reproducibly per step.
//! - [`prefetch`]: worker threads that load upcoming items ahead of the consumer, in order, with bounded memory;
//!   [`loader`] streams decoded training samples through it.
//! - [`summary`]: what `dggt inspect` reports about a scene; [`window`]: a window of frames checked against a
//!   scene's.
//! - [`text`], [`npy`], [`images`], [`io`]: untrusted-input readers and atomic writers; [`confined`]: paths that
//!   untrusted files name, kept inside their folder; [`output_lock`]: one command at a time per output.
//! - [`random`]: the seeded generator (SplitMix64) of the sampler, the stress suite, and test and bench scenes.
//!
//! Every reader returns a [`DataError`] naming the file and what was expected; nothing here panics on bad input.

pub mod confined;
pub mod decoded;
pub mod depth_flow;
mod error;
pub mod export;
pub mod images;
pub mod index;
pub mod instances;
pub mod io;
pub mod kitti;
pub mod layout;
pub mod lidar;
pub mod loader;
pub mod mix;
pub mod npy;
mod open;
pub mod output_lock;
pub mod prefetch;
pub mod preprocess;
pub mod random;
pub mod sampler;
pub mod scene;
pub mod summary;
pub mod text;
pub mod variant;
pub mod views;
pub mod window;

pub use decoded::DecodedViews;
pub use depth_flow::{DepthFlowMap, DepthSource, FlowOrigin};
pub use error::{DataError, Result};
pub use export::{ExportOptions, read_export};
pub use index::{DatasetIndex, DatasetSpec, HeldOut, IndexedScene, Split};
pub use kitti::read_kitti_odometry;
pub use layout::{DynamicMaskKind, ExportLayout};
pub use loader::{DatasetSampling, LoadedSample, LoaderOptions, dataset_stream, load_sample, training_stream};
pub use mix::SceneMix;
pub use open::{LogLayout, open_scene, open_scene_as};
pub use prefetch::Prefetcher;
pub use preprocess::{BinaryMask, PlanarImage, Preprocess, PreprocessPlan};
pub use sampler::{Sampler, SamplerConfig, TrainingSample};
pub use scene::{Scene, SceneCamera, SceneFrame, SceneSource, View, ViewFiles};
pub use summary::SceneSummary;
pub use variant::ExportVariant;
pub use views::{PreparedView, prepare_view, prepare_view_cached};
pub use window::{FramesOutside, frames_outside};
