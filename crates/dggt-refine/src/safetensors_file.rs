//! The workspace's safetensors reader ([`dggt_model::safetensors_file`]) with this crate's error type, for
//! callers whose errors convert from [`RefineError`]: open a file, check a tensor's element size, find its bytes.

use std::ops::{Deref, Range};
use std::path::Path;

pub use dggt_model::safetensors_file::TensorEntry;

use crate::error::RefineError;

/// An open safetensors file and its header; everything of [`dggt_model::safetensors_file::SafetensorsFile`]
/// is reachable through it.
pub struct SafetensorsFile(dggt_model::safetensors_file::SafetensorsFile);

impl SafetensorsFile {
    /// Opens `path` and reads and checks its header.
    pub fn open(path: &Path) -> Result<Self, RefineError> {
        Ok(Self(dggt_model::safetensors_file::SafetensorsFile::open(path)?))
    }

    /// The entry of tensor `name`, checked: its byte range holds exactly its shape of `element_bytes`-byte values.
    pub fn entry(&self, name: &str, element_bytes: usize) -> Result<&TensorEntry, RefineError> {
        let entry = self.0.entry(name)?;
        let length = entry.shape.iter().try_fold(element_bytes, |bytes, &side| bytes.checked_mul(side));
        if length.and_then(|bytes| u64::try_from(bytes).ok()) != Some(entry.byte_len()) {
            let ([begin, end], shape) = (entry.data_offsets, &entry.shape);
            return Err(RefineError::file(
                self.0.path(),
                format!("tensor '{name}': offsets {begin}..{end} for shape {shape:?}"),
            ));
        }
        Ok(entry)
    }

    /// Where tensor `name`'s data lies in the file (absolute byte positions).
    pub fn byte_range(&self, name: &str) -> Result<Range<u64>, RefineError> {
        Ok(self.0.byte_range(name)?)
    }
}

impl Deref for SafetensorsFile {
    type Target = dggt_model::safetensors_file::SafetensorsFile;

    fn deref(&self) -> &Self::Target {
        &self.0
    }
}
