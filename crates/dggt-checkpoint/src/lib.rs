//! The checkpoint folders of this project's training runs, as inference and the run machinery both read them:
//! one format, whoever wrote the folder and whoever reads it.
//!
//! - [`files`]: the names of a folder's files and of the `latest` pointer;
//! - [`checksums`]: the manifest of each file's size and CRC-32C, written with the folder and checked before a
//!   file is used;
//! - [`folders`]: which folder to use (complete, its files intact), the newest intact one of a run's;
//! - [`network`]: the network's configuration and preprocessing read, and any module's weights written and read
//!   as burnpack files.
//!
//! What a run adds to a checkpoint (the optimiser's state, the run state's contents, a trainer's own files) and
//! writes it with is `dggt-run`'s and its trainers'; a network from any other checkpoint (the release's `.pt`,
//! VGGT-1B) is `dggt-infer`'s.

pub mod checksums;
mod error;
pub mod files;
pub mod folders;
pub mod network;

pub use checksums::{Purpose, Verified};
pub use error::{CheckpointError, Damage};
pub use files::{LATEST, MANIFEST_FILE, MODEL_CONFIG_FILE, MODEL_FILE, PREPROCESS_FILE, STATE_FILE};
pub use folders::{checkpoint_dir, latest, verified};
pub use network::{deferred_tensor, load_model, load_module_file, read_model_config, read_preprocess, save_model};
