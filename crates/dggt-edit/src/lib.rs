//! Scene editing: the moving objects of a saved reconstruction (`scene.safetensors`, written by
//! `dggt reconstruct`) removed, moved along their trajectories, or inserted from another reconstruction, and the
//! edited scene rendered at any camera and time (`dggt edit`).
//!
//! The data flow, one module per step:
//!
//! 1. [`request`]: the edits as the user writes them (`--remove ID`, `--move ID:DX,DY,DZ,YAW`,
//!    `--insert SCENE:ID@X,Y,Z,YAW`), parsed and checked;
//! 2. [`frame`]: the world's up axis and the turns about it that yaws mean;
//! 3. [`object`]: an object taken out of one reconstruction with its trajectory, drawn in another;
//! 4. [`apply`]: the edits applied to a scene, every argument checked before anything changes;
//! 5. [`outputs`]: renders, before/after images, hole masks, per-time PLYs and `edit.json` written.
//!
//! Conventions: positions and offsets are in the reconstruction's world (the frame and units of its
//! `cameras.json`: the first input camera's frame, OpenCV axes, the network's units, when cameras were
//! predicted); yaws in degrees on the command line, counter-clockwise seen from above (about the world's up
//! axis, [`frame::WorldUp`]); times are the scene's own times (those of `scene.safetensors`' input views).

pub mod apply;
mod error;
pub mod frame;
pub mod object;
pub mod outputs;
pub mod request;

pub use apply::{EditedScene, apply_edits};
pub use error::EditError;
pub use outputs::{EditJob, EditOptions, EditSummary, prepare_edits, write_edits};
pub use request::{Edit, EditKind, Insertion};
