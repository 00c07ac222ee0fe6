//! A safetensors file read piece by piece: its header first (an 8-byte little-endian length, then that many
//! bytes of JSON naming each tensor's type, shape and byte range relative to the data that follows, and
//! optional text metadata), then only the byte ranges a caller asks for. Every size in the header is checked
//! against the file's length without overflow, so a truncated or hostile file is an error naming it, never a
//! panic or an allocation of whatever the header claims.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::error::RefineError;

/// An open safetensors file and its header.
pub struct SafetensorsFile {
    path: PathBuf,
    file: File,
    pub tensors: BTreeMap<String, TensorEntry>,
    pub metadata: HashMap<String, String>,
    /// Where the tensors' data begins in the file.
    data_start: u64,
}

/// One tensor of the header: its type name (`F32`, `BF16`, ...), shape and byte range in the data.
#[derive(Debug, Clone, serde::Deserialize)]
pub struct TensorEntry {
    pub dtype: String,
    pub shape: Vec<usize>,
    pub data_offsets: [u64; 2],
}

/// Headers beyond this are refused (the format's own bound).
const MAX_HEADER_BYTES: u64 = 100_000_000;

impl SafetensorsFile {
    /// Opens `path` and reads its header.
    pub fn open(path: &Path) -> Result<Self, RefineError> {
        let mut file = File::open(path).map_err(|e| RefineError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| RefineError::io(path, e))?.len();
        let invalid = |detail: String| RefineError::file(path, format!("not a safetensors file: {detail}"));
        let mut length = [0u8; 8];
        file.read_exact(&mut length).map_err(|e| invalid(format!("no header length ({e})")))?;
        let length = u64::from_le_bytes(length);
        if length > MAX_HEADER_BYTES || 8 + length > file_len {
            return Err(invalid(format!("a header of {length} bytes in a file of {file_len}")));
        }
        let mut json = vec![0u8; length as usize];
        file.read_exact(&mut json).map_err(|e| invalid(format!("header not readable ({e})")))?;
        let mut entries: BTreeMap<String, serde_json::Value> =
            serde_json::from_slice(&json).map_err(|e| invalid(format!("header: {e}")))?;
        let metadata = match entries.remove("__metadata__") {
            Some(value) => serde_json::from_value(value).map_err(|e| invalid(format!("metadata: {e}")))?,
            None => HashMap::new(),
        };
        let data_start = 8 + length;
        let mut tensors = BTreeMap::new();
        for (name, value) in entries {
            let entry: TensorEntry =
                serde_json::from_value(value).map_err(|e| invalid(format!("tensor '{name}': {e}")))?;
            if entry.data_offsets[1] > file_len - data_start {
                return Err(invalid(format!("tensor '{name}' ends past the end of the file")));
            }
            tensors.insert(name, entry);
        }
        Ok(Self { path: path.to_path_buf(), file, tensors, metadata, data_start })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The entry of tensor `name`, checked: its byte range holds exactly `shape` of `element_bytes`-byte values.
    pub fn entry(&self, name: &str, element_bytes: usize) -> Result<&TensorEntry, RefineError> {
        let entry =
            self.tensors.get(name).ok_or_else(|| RefineError::file(&self.path, format!("no tensor '{name}'")))?;
        let [begin, end] = entry.data_offsets;
        let length = entry.shape.iter().try_fold(element_bytes, |bytes, &side| bytes.checked_mul(side));
        if end < begin || length != usize::try_from(end - begin).ok() {
            let shape = &entry.shape;
            return Err(RefineError::file(
                &self.path,
                format!("tensor '{name}': offsets {begin}..{end} for shape {shape:?}"),
            ));
        }
        Ok(entry)
    }

    /// Where tensor `name`'s data lies in the file (absolute byte positions).
    pub fn byte_range(&self, name: &str) -> Result<Range<u64>, RefineError> {
        let entry =
            self.tensors.get(name).ok_or_else(|| RefineError::file(&self.path, format!("no tensor '{name}'")))?;
        let [begin, end] = entry.data_offsets;
        Ok(self.data_start + begin..self.data_start + end)
    }

    /// Reads `out.len()` bytes of tensor `name`'s data from byte `offset` of it (checked against its range).
    pub fn read_bytes(&mut self, name: &str, offset: u64, out: &mut [u8]) -> Result<(), RefineError> {
        let range = self.byte_range(name)?;
        let inside = range
            .start
            .checked_add(offset)
            .and_then(|start| start.checked_add(out.len() as u64))
            .is_some_and(|stop| stop <= range.end);
        if !inside {
            return Err(RefineError::file(
                &self.path,
                format!("tensor '{name}': {} bytes at {offset} lie outside it", out.len()),
            ));
        }
        self.file
            .seek(SeekFrom::Start(range.start + offset))
            .and_then(|_| self.file.read_exact(out))
            .map_err(|e| RefineError::file(&self.path, format!("tensor '{name}' not readable: {e}")))
    }
}
