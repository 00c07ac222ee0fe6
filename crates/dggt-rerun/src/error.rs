//! Errors of writing a recording: each names the file or entity at fault.

use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum RerunError {
    #[error(transparent)]
    Format(#[from] dggt_formats::FormatError),
    #[error("{}: {detail}", path.display())]
    Input { path: PathBuf, detail: String },
    #[error("writing the recording {}: {detail}", path.display())]
    Recording { path: PathBuf, detail: String },
    #[error("opening the recording to {destination}: {detail}")]
    Opening { destination: String, detail: String },
    #[error("logging {entity}: {detail}")]
    Entity { entity: String, detail: String },
}
