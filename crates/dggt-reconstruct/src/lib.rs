//! `dggt reconstruct`: unposed images in; per-frame cameras, depth, dynamic and sky maps, 4D Gaussians and
//! renders at any time out, from one forward pass of the network.
//!
//! - [`inputs`]: the views of an image folder or a scene export, in one size;
//! - [`network`]: the network of a trainer checkpoint or a release / VGGT file, and what it lacks;
//! - [`forward`]: the forward pass with the dense heads run a few frames at a time;
//! - [`pipeline`]: cameras, maps, Gaussians and renders written in the formats of `dggt-export`;
//! - [`align`]: similarity alignment of predicted to reference camera centres (the pose report);
//! - [`summary`]: counts, times and peak memory, printed and saved as `summary.json`.

pub mod align;
mod error;
pub mod forward;
pub mod inputs;
pub mod network;
pub mod pipeline;
pub mod summary;

pub use error::ReconstructError;
pub use network::{Architecture, CheckpointInfo, LoadedNetwork, load_network};
pub use pipeline::{ReconstructOptions, TimeRequest, reconstruct};
pub use summary::Summary;
