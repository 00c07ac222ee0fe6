//! Driving-scene data for dggt: everything between files on disk and the tensors a training step consumes.
//!
//! - [`layout`]: file names of the scene-export layout (drivestudio / OmniRe).
//! - [`text`], [`npy`], [`images`], [`io`]: untrusted-input readers and atomic writers.
//!
//! Every reader returns a [`DataError`] naming the file and what was expected; nothing here panics on bad input.

mod error;
pub mod images;
pub mod io;
pub mod layout;
pub mod npy;
pub mod text;

pub use error::{DataError, Result};
pub use layout::{DynamicMaskKind, ExportLayout};
