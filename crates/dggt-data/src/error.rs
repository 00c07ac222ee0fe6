//! Errors of the data layer. Every variant names the file it concerns and says what was expected, because a
//! scene export is untrusted input and the user needs to know which of thousands of files is at fault.

use std::path::{Path, PathBuf};

use dggt_geom::GeomError;

#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}: expected {expected}, found {found}", path.display())]
    Malformed { path: PathBuf, expected: String, found: String },
    #[error("{}: {source}", path.display())]
    Geometry { path: PathBuf, source: GeomError },
    #[error("{}: cannot decode image: {source}", path.display())]
    Image { path: PathBuf, source: image::ImageError },
    #[error("{}: {outside}", root.display())]
    FramesOutside { root: PathBuf, outside: crate::window::FramesOutside },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("loading failed: {0}")]
    Worker(String),
}

impl DataError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io { path: path.to_owned(), source }
    }

    pub fn malformed(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        Self::Malformed { path: path.to_owned(), expected: expected.into(), found: found.into() }
    }

    pub fn geometry(path: &Path, source: GeomError) -> Self {
        Self::Geometry { path: path.to_owned(), source }
    }

    /// The file this error concerns, when there is one.
    pub fn path(&self) -> Option<&Path> {
        match self {
            Self::Io { path, .. }
            | Self::Malformed { path, .. }
            | Self::Geometry { path, .. }
            | Self::Image { path, .. }
            | Self::FramesOutside { root: path, .. } => Some(path),
            Self::Config(_) | Self::Worker(_) => None,
        }
    }
}

pub type Result<T, E = DataError> = std::result::Result<T, E>;
