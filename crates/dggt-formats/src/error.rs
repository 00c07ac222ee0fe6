//! Errors of writing and reading the output files; each names the file.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}: expected {expected}, found {found}", path.display())]
    Malformed { path: PathBuf, expected: String, found: String },
    #[error("{}: {detail}", path.display())]
    Invalid { path: PathBuf, detail: String },
    /// A PLY file (or the cloud to write as one) that is not what this project writes.
    #[error("{}: expected a binary little-endian float32 vertex PLY: {source}", path.display())]
    Ply { path: PathBuf, source: crate::ply::PlyError },
    /// Writing a file (the error names it).
    #[error(transparent)]
    Write(#[from] dggt_data::DataError),
}

impl FormatError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io { path: path.to_owned(), source }
    }

    pub(crate) fn malformed(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        Self::Malformed { path: path.to_owned(), expected: expected.into(), found: found.into() }
    }

    pub(crate) fn invalid(path: &Path, detail: impl Into<String>) -> Self {
        Self::Invalid { path: path.to_owned(), detail: detail.into() }
    }
}
