//! `dggt reconstruct`: unposed images in; per-frame cameras, depth, dynamic and sky maps, 4D Gaussians and
//! renders at any time out, from one forward pass of the network (run through `dggt-infer`).
//!
//! - [`pipeline`]: cameras, maps, Gaussians and renders written in the formats of `dggt-formats`;
//! - [`align`]: similarity alignment of predicted to reference camera centres (the pose report);
//! - [`finite`]: every value checked finite before its file is written;
//! - [`summary`]: counts, times and peak memory, printed and saved as `summary.json`;
//! - [`times`]: the requested render times, and [`volume`]: the largest output they could give, both checked
//!   before any work.

pub mod align;
mod error;
pub mod finite;
pub mod pipeline;
pub mod summary;
pub mod times;
pub mod volume;

pub use error::ReconstructError;
pub use pipeline::{ReconstructOptions, TimeRequest, reconstruct};
pub use summary::Summary;
pub use volume::{DEFAULT_MAX_OUTPUT_BYTES, GB, OutputEstimate};
