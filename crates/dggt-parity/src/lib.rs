//! Parity with the reference implementations: a folder of reference vectors is opened, the port is run on its
//! inputs, and every reference output is compared with the port's value into one [`ParityReport`].
//!
//! - [`vectors`]: the network's vector folders (`config.json`, weights, `inputs.safetensors`,
//!   `outputs.safetensors`);
//! - [`network`]: the DGGT network run on them, each reference output reproduced by name (with
//!   [`network::release_render`], the release's own inference render of the scene);
//! - [`refiner`]: the refiner's vector folders, run in both modes and compared tensor by tensor;
//! - [`tolerance`]: how large a difference each harness allows;
//! - [`report`]: the rows, their statuses and the pass rule shared by both: every reference output was compared
//!   and is within tolerance.

mod error;
pub mod network;
pub mod refiner;
pub mod report;
pub mod tolerance;
pub mod vectors;

pub use error::ParityError;
pub use report::{ParityReport, ParityRow, Status};
pub use vectors::{HostTensor, ParityVectors};
