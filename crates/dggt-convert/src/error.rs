//! Errors of the converters. Raw datasets are untrusted input at the scale of thousands of files, so every error
//! names the file, the record (or row) within it, and what was expected there.

use std::path::{Path, PathBuf};

/// Why a raw log could not be converted.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    /// The TFRecord framing is broken: a bad checksum or a record cut short.
    #[error("{}: record {record}: expected {expected}, found {found}", path.display())]
    Framing { path: PathBuf, record: usize, expected: String, found: String },
    /// A record's payload is not a valid protobuf of the expected message.
    #[error("{}: record {record}: cannot decode {message}: {source}", path.display())]
    Decode { path: PathBuf, record: usize, message: &'static str, source: prost::DecodeError },
    /// A record decodes but its content breaks a rule the converter relies on.
    #[error("{}: record {record}: expected {expected}, found {found}", path.display())]
    Content { path: PathBuf, record: usize, expected: String, found: String },
    /// A table (Feather file) lacks a column, has the wrong type or a bad value.
    #[error("{}: expected {expected}, found {found}", path.display())]
    Table { path: PathBuf, expected: String, found: String },
    /// A frame's boxes give no scene flow (a box without a size, frames at one time).
    #[error("{}: frame {frame}: {source}", path.display())]
    BoxFlow { path: PathBuf, frame: usize, source: crate::box_flow::BoxFlowError },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    /// Another command is converting into the scene's folder.
    #[error(transparent)]
    Lock(#[from] dggt_data::output_lock::LockError),
    /// A nuScenes version given by name is not a plain folder name.
    #[error("{name:?} is not a folder name (a nuScenes version such as v1.0-mini)")]
    VersionName { name: String },
    #[error("cannot serialise {what}: {source}")]
    Json { what: &'static str, source: serde_json::Error },
}

impl ConvertError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io { path: path.to_owned(), source }
    }
}

/// Where in a raw file a piece of content came from, for errors about it.
#[derive(Debug, Clone, Copy)]
pub struct RecordAt<'a> {
    pub path: &'a Path,
    pub record: usize,
}

impl RecordAt<'_> {
    /// An error about this record's content.
    pub fn content(&self, expected: impl Into<String>, found: impl Into<String>) -> ConvertError {
        ConvertError::Content {
            path: self.path.to_owned(),
            record: self.record,
            expected: expected.into(),
            found: found.into(),
        }
    }
}

pub type Result<T, E = ConvertError> = std::result::Result<T, E>;
