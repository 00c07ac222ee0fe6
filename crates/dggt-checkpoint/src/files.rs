//! The files of a checkpoint folder that inference and the run machinery both read or write. A run writes
//! `checkpoints/step-NNNNNNNN/` folders and a `checkpoints/latest` pointer naming the newest complete one; each
//! folder holds the network, its configuration and preprocessing, the run state and the manifest of their
//! checksums, beside the files a trainer adds of its own (the optimiser's state, say).

/// The pointer file naming the newest complete checkpoint folder.
pub const LATEST: &str = "latest";
/// The network's weights in a checkpoint folder.
pub const MODEL_FILE: &str = "model.bpk";
/// The network's configuration in a checkpoint folder.
pub const MODEL_CONFIG_FILE: &str = "model.json";
/// The input preprocessing of training in a checkpoint folder.
pub const PREPROCESS_FILE: &str = "preprocess.json";
/// The run state in a checkpoint folder; its presence marks the folder complete.
pub const STATE_FILE: &str = "state.json";
/// The manifest of a checkpoint folder: the size and checksum of each of its files ([`crate::checksums`]).
pub const MANIFEST_FILE: &str = "checksums.json";
