//! Errors of checkpoint folders: a file that cannot be read or written, or holds something unexpected, and a
//! folder whose files do not match their manifest ([`Damage`]); each names the file or folder at fault.

use std::path::PathBuf;

use crate::files::MANIFEST_FILE;

/// Why a checkpoint folder could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// A checkpoint file or folder that cannot be read or written, or holds something unexpected.
    #[error("checkpoint {}: {detail}", path.display())]
    File { path: PathBuf, detail: String },
    /// A checkpoint folder whose files do not match its manifest ([`crate::checksums`]).
    #[error(
        "checkpoint {}: {damage}: the checkpoint is damaged and not used (an earlier checkpoint of the run may be \
         intact)",
        dir.display()
    )]
    Damaged { dir: PathBuf, damage: Damage },
}

impl CheckpointError {
    // Takes any error by value, like `impl Into<String>`, so `map_err(|e| ..(path, e))` reads plainly.
    #[allow(clippy::needless_pass_by_value)]
    pub(crate) fn file(path: impl Into<PathBuf>, detail: impl ToString) -> Self {
        Self::File { path: path.into(), detail: detail.to_string() }
    }
}

/// A file of a checkpoint folder that does not match the manifest.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Damage {
    #[error("{file} is missing (the manifest lists it)")]
    Missing { file: String },
    #[error("{file}: checksum mismatch (the file has {found} bytes where the manifest records {recorded})")]
    Size { file: String, recorded: u64, found: u64 },
    #[error("{file}: checksum mismatch (CRC-32C {found:08x} where the manifest records {recorded:08x})")]
    Checksum { file: String, recorded: u32, found: u32 },
    #[error("{file} cannot be read: {detail}")]
    Unreadable { file: String, detail: String },
    #[error("{MANIFEST_FILE} cannot be read: {detail}")]
    Manifest { detail: String },
}
