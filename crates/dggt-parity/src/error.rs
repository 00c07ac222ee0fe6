//! Errors that stop a parity run before anything is compared: a vector folder that is missing or incomplete, an
//! input of the wrong shape, or the port failing to load or run. A reference output the port cannot reproduce is
//! not an error but a failing row of the report ([`crate::report::Status`]).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ParityError {
    #[error("parity vectors at {}: no such folder", dir.display())]
    NoFolder { dir: PathBuf },
    /// A file every vector folder holds.
    #[error("parity vectors at {}: {file} is missing (a vector folder holds {holds})", dir.display())]
    MissingFile { dir: PathBuf, file: &'static str, holds: String },
    #[error("parity vectors at {}: no weights: neither {} nor {}", dir.display(), files[0], files[1])]
    NoWeights { dir: PathBuf, files: [&'static str; 2] },
    #[error("parity vectors at {}: inputs.safetensors has no `{name}`", dir.display())]
    MissingInput { dir: PathBuf, name: &'static str },
    /// An input tensor whose shape or type is not the one the port takes.
    #[error("parity vectors at {}: `{name}` is {found}, not {expected}", dir.display())]
    BadInput { dir: PathBuf, name: &'static str, expected: String, found: String },
    #[error(transparent)]
    Safetensors(#[from] dggt_model::safetensors_file::SafetensorsError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Refine(#[from] dggt_refine::RefineError),
}
