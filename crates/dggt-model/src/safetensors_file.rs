//! The one safetensors reader of the workspace: a file read piece by piece, its header first (an 8-byte
//! little-endian length, then that many bytes of JSON giving each tensor's type, shape and byte range relative
//! to the data that follows, and optional text metadata), then only the tensors a caller asks for.
//!
//! Every size in the header is checked against the file's length without overflow when the file is opened, and
//! every tensor of a known type must span exactly its shape's bytes, so a truncated or hostile file is an error
//! naming the file (and the tensor), never a panic or an allocation of whatever the header claims. Tensors are
//! read as stored ([`SafetensorsFile::read_data`]) or widened to `f32` host values ([`SafetensorsFile::read_f32`]).
//!
//! ```no_run
//! # fn main() -> Result<(), dggt_model::safetensors_file::SafetensorsError> {
//! use dggt_model::safetensors_file::SafetensorsFile;
//! let mut file = SafetensorsFile::open("outputs.safetensors")?;
//! for name in file.names_in_file_order() {
//!     let entry = file.entry(&name)?;
//!     println!("{name}: {} {:?}", entry.dtype, entry.shape);
//! }
//! let depth = file.read_f32("depth")?;
//! # Ok(()) }
//! ```

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};

use burn::tensor::{DType, TensorData};

/// Headers beyond this are refused rather than allocated (the format's own bound; the release's header is about
/// 150 kB).
const MAX_HEADER_BYTES: u64 = 100_000_000;

/// What went wrong reading a safetensors file; each names the file, and the tensor where there is one.
#[derive(Debug, thiserror::Error)]
pub enum SafetensorsError {
    #[error("reading {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The header is unreadable, or its sizes do not fit the file.
    #[error("{}: not a safetensors file: {detail}", path.display())]
    Malformed { path: PathBuf, detail: String },
    #[error(transparent)]
    BadSpan(Box<BadSpan>),
    #[error("{}: no tensor '{name}'", path.display())]
    MissingTensor { path: PathBuf, name: String },
    /// A tensor whose stored type the caller cannot take (or burn cannot hold).
    #[error("{}: tensor '{name}' has type {dtype}, expected {expected}", path.display())]
    UnsupportedDtype { path: PathBuf, name: String, dtype: String, expected: &'static str },
    #[error("{}: tensor '{name}' not readable: {source}", path.display())]
    TensorUnreadable {
        path: PathBuf,
        name: String,
        #[source]
        source: std::io::Error,
    },
    /// A read of bytes outside a tensor's range.
    #[error("{}: tensor '{name}': {len} bytes at {offset} lie outside it", path.display())]
    OutsideTensor { path: PathBuf, name: String, offset: u64, len: usize },
}

/// A tensor whose byte range lies outside the data section or does not span its shape.
#[derive(Debug, thiserror::Error)]
#[error("{}: not a safetensors file: tensor '{name}': {}", path.display(), self.what_is_wrong())]
pub struct BadSpan {
    pub path: PathBuf,
    pub name: String,
    pub entry: TensorEntry,
    /// The length of the data section.
    pub data_len: u64,
    /// The bytes the shape needs (`None` when that overflows).
    pub expected: Option<usize>,
}

impl BadSpan {
    /// A cut-short file (the range runs past the end of the data), or a range that does not fit the shape.
    fn what_is_wrong(&self) -> String {
        let [begin, end] = self.entry.data_offsets;
        let expected = self.expected.map_or("too many".to_string(), |bytes| bytes.to_string());
        let needed = format!("expected {expected} bytes for {} {:?}", self.entry.dtype, self.entry.shape);
        if end > self.data_len || begin > end {
            let data_len = self.data_len;
            return format!(
                "bytes {begin}..{end} run past the end of the data ({data_len} bytes; {needed}): cut short"
            );
        }
        format!("bytes {begin}..{end} ({} bytes), {needed}", end - begin)
    }
}

/// One tensor of the header: its type name as stored (`F32`, `BF16`, `I64`, ...), shape and byte range in the
/// data section.
#[derive(Debug, Clone, PartialEq, Eq, serde::Deserialize)]
pub struct TensorEntry {
    pub dtype: String,
    pub shape: Vec<usize>,
    pub data_offsets: [u64; 2],
}

impl TensorEntry {
    /// The burn element type of the stored type; `None` for types burn cannot hold (sub-byte floats, ...).
    /// Booleans are bytes of 0 or 1, read as `U8`.
    pub fn burn_dtype(&self) -> Option<DType> {
        Some(match self.dtype.as_str() {
            "F64" => DType::F64,
            "F32" => DType::F32,
            "F16" => DType::F16,
            "BF16" => DType::BF16,
            "I64" => DType::I64,
            "I32" => DType::I32,
            "I16" => DType::I16,
            "I8" => DType::I8,
            "U64" => DType::U64,
            "U32" => DType::U32,
            "U16" => DType::U16,
            "U8" | "BOOL" => DType::U8,
            _ => return None,
        })
    }

    /// Whether the stored type is a floating-point one burn holds (`F64`, `F32`, `F16`, `BF16`).
    pub fn is_float(&self) -> bool {
        matches!(self.dtype.as_str(), "F64" | "F32" | "F16" | "BF16")
    }

    /// The number of bytes the tensor spans in the data section.
    pub fn byte_len(&self) -> u64 {
        self.data_offsets[1] - self.data_offsets[0]
    }
}

/// A tensor as `f32` host values: row-major, with its shape.
#[derive(Debug, Clone, PartialEq)]
pub struct F32Tensor {
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

/// An open safetensors file and its header.
pub struct SafetensorsFile {
    path: PathBuf,
    file: File,
    tensors: BTreeMap<String, TensorEntry>,
    /// The header's text metadata (`__metadata__`); empty when it has none.
    pub metadata: HashMap<String, String>,
    /// Where the tensors' data begins in the file.
    data_start: u64,
}

impl SafetensorsFile {
    /// Opens `path` and reads and checks its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, SafetensorsError> {
        let path = path.as_ref();
        let io = |source| SafetensorsError::Io { path: path.to_path_buf(), source };
        let malformed = |detail: String| SafetensorsError::Malformed { path: path.to_path_buf(), detail };
        let mut file = File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut length = [0u8; 8];
        file.read_exact(&mut length).map_err(|e| malformed(format!("no header length ({e})")))?;
        let length = u64::from_le_bytes(length);
        if length > MAX_HEADER_BYTES || length > file_len - 8 {
            return Err(malformed(format!("header length {length} does not fit a {file_len}-byte file")));
        }
        let mut json = vec![0u8; length as usize];
        file.read_exact(&mut json).map_err(|e| malformed(format!("header not readable ({e})")))?;
        let mut entries: BTreeMap<String, serde_json::Value> =
            serde_json::from_slice(&json).map_err(|e| malformed(format!("header: {e}")))?;
        let metadata = match entries.remove("__metadata__") {
            Some(value) => serde_json::from_value(value).map_err(|e| malformed(format!("metadata: {e}")))?,
            None => HashMap::new(),
        };
        let data_start = 8 + length;
        let data_len = file_len - data_start;
        let mut tensors = BTreeMap::new();
        for (name, value) in entries {
            let entry: TensorEntry =
                serde_json::from_value(value).map_err(|e| malformed(format!("tensor '{name}': {e}")))?;
            check_span(path, &name, &entry, data_len)?;
            tensors.insert(name, entry);
        }
        Ok(Self { path: path.to_path_buf(), file, tensors, metadata, data_start })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every tensor's header entry, by name.
    pub fn entries(&self) -> &BTreeMap<String, TensorEntry> {
        &self.tensors
    }

    /// Every tensor's name, in the order of the tensors' data in the file (the order they were written in).
    pub fn names_in_file_order(&self) -> Vec<String> {
        let mut names: Vec<(&String, &TensorEntry)> = self.tensors.iter().collect();
        names.sort_by_key(|(_, entry)| entry.data_offsets);
        names.into_iter().map(|(name, _)| name.clone()).collect()
    }

    /// The header entry of tensor `name`.
    pub fn entry(&self, name: &str) -> Result<&TensorEntry, SafetensorsError> {
        self.tensors
            .get(name)
            .ok_or_else(|| SafetensorsError::MissingTensor { path: self.path.clone(), name: name.to_string() })
    }

    /// Where tensor `name`'s data lies in the file (absolute byte positions).
    pub fn byte_range(&self, name: &str) -> Result<Range<u64>, SafetensorsError> {
        let [begin, end] = self.entry(name)?.data_offsets;
        Ok(self.data_start + begin..self.data_start + end)
    }

    /// Reads `out.len()` bytes of tensor `name`'s data from byte `offset` of it (checked against its range).
    pub fn read_bytes(&mut self, name: &str, offset: u64, out: &mut [u8]) -> Result<(), SafetensorsError> {
        let range = self.byte_range(name)?;
        let inside = range
            .start
            .checked_add(offset)
            .and_then(|start| start.checked_add(out.len() as u64))
            .is_some_and(|stop| stop <= range.end);
        if !inside {
            let (path, name) = (self.path.clone(), name.to_string());
            return Err(SafetensorsError::OutsideTensor { path, name, offset, len: out.len() });
        }
        read_at(&mut self.file, range.start + offset, out).map_err(|source| SafetensorsError::TensorUnreadable {
            path: self.path.clone(),
            name: name.to_string(),
            source,
        })
    }

    /// Tensor `name` as stored (booleans as `U8`); an error for a type burn cannot hold.
    pub fn read_data(&mut self, name: &str) -> Result<TensorData, SafetensorsError> {
        let entry = self.entry(name)?;
        let dtype = entry.burn_dtype().ok_or_else(|| SafetensorsError::UnsupportedDtype {
            path: self.path.clone(),
            name: name.to_string(),
            dtype: entry.dtype.clone(),
            expected: "a float, integer or boolean type",
        })?;
        let shape = entry.shape.clone();
        let mut bytes = vec![0u8; entry.byte_len() as usize];
        self.read_bytes(name, 0, &mut bytes)?;
        Ok(TensorData::from_bytes_vec(bytes, shape, dtype))
    }

    /// Every tensor as stored, by name.
    pub fn read_all_data(&mut self) -> Result<BTreeMap<String, TensorData>, SafetensorsError> {
        let names: Vec<String> = self.tensors.keys().cloned().collect();
        names.into_iter().map(|name| Ok((name.clone(), self.read_data(&name)?))).collect()
    }

    /// Tensor `name` widened (or narrowed) to `f32`, whatever its stored float, integer or boolean type.
    pub fn read_f32(&mut self, name: &str) -> Result<F32Tensor, SafetensorsError> {
        let data = self.read_data(name)?;
        let shape = data.shape().to_vec();
        let values = data.convert::<f32>().try_into_vec::<f32>().map_err(|e| SafetensorsError::Malformed {
            path: self.path.clone(),
            detail: format!("tensor '{name}' not convertible to f32: {e:?}"),
        })?;
        Ok(F32Tensor { shape, values })
    }
}

/// Reads `out.len()` bytes at `position` of `file`.
fn read_at(file: &mut File, position: u64, out: &mut [u8]) -> std::io::Result<()> {
    file.seek(SeekFrom::Start(position))?;
    file.read_exact(out)
}

/// Checks that `entry`'s byte range lies inside a data section of `data_len` bytes and, for a type of known
/// size, spans exactly its shape's bytes.
fn check_span(path: &Path, name: &str, entry: &TensorEntry, data_len: u64) -> Result<(), SafetensorsError> {
    let [begin, end] = entry.data_offsets;
    let element = entry.burn_dtype().map(|dtype| dtype.size());
    let expected = element.and_then(|bytes| entry.shape.iter().try_fold(bytes, |bytes, &side| bytes.checked_mul(side)));
    let spans_shape =
        element.is_none() || expected.and_then(|bytes| u64::try_from(bytes).ok()) == end.checked_sub(begin);
    if end < begin || end > data_len || !spans_shape {
        let (path, name, entry) = (path.to_path_buf(), name.to_string(), entry.clone());
        return Err(SafetensorsError::BadSpan(Box::new(BadSpan { path, name, entry, data_len, expected })));
    }
    Ok(())
}

/// Reads `len` bytes at `position` of the file at `path`: for readers that defer each tensor's read until it is
/// needed, with the range from [`SafetensorsFile::byte_range`].
pub fn read_file_range(path: &Path, range: Range<u64>) -> std::io::Result<Vec<u8>> {
    let mut file = File::open(path)?;
    let mut bytes = vec![0u8; (range.end - range.start) as usize];
    read_at(&mut file, range.start, &mut bytes)?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, header: &str, data: &[u8]) -> PathBuf {
        let path = dir.join("t.safetensors");
        let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(data);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn tensors_read_as_f32_in_file_order() {
        let dir = tempfile::tempdir().unwrap();
        let header = r#"{"b":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},"a":{"dtype":"I64","shape":[1],"data_offsets":[8,16]},"__metadata__":{"k":"v"}}"#;
        let mut data: Vec<u8> = [1.5f32, -2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        data.extend_from_slice(&7i64.to_le_bytes());
        let mut file = SafetensorsFile::open(write(dir.path(), header, &data)).unwrap();
        assert_eq!(file.names_in_file_order(), ["b", "a"]);
        assert_eq!(file.metadata["k"], "v");
        assert_eq!(file.read_f32("b").unwrap(), F32Tensor { shape: vec![2], values: vec![1.5, -2.0] });
        assert_eq!(file.read_f32("a").unwrap().values, [7.0]);
        assert_eq!(file.read_data("a").unwrap().try_into_vec::<i64>().unwrap(), [7]);
        let missing = file.read_f32("c").unwrap_err().to_string();
        assert!(missing.contains("t.safetensors") && missing.contains("no tensor 'c'"), "{missing}");
    }

    #[test]
    fn sizes_not_fitting_the_file_are_errors_naming_file_and_tensor() {
        let dir = tempfile::tempdir().unwrap();
        let header = r#"{"x":{"dtype":"F32","shape":[4],"data_offsets":[0,16]}}"#;
        let short = SafetensorsFile::open(write(dir.path(), header, &[0; 8])).err().unwrap().to_string();
        assert!(short.contains("t.safetensors") && short.contains("'x'") && short.contains("expected 16"), "{short}");
        let header = r#"{"x":{"dtype":"F32","shape":[3],"data_offsets":[0,16]}}"#;
        let wrong = SafetensorsFile::open(write(dir.path(), header, &[0; 16])).err().unwrap().to_string();
        assert!(wrong.contains("not a safetensors file") && wrong.contains("expected 12 bytes"), "{wrong}");
        let path = dir.path().join("t.safetensors");
        std::fs::write(&path, 1000u64.to_le_bytes()).unwrap();
        let header = SafetensorsFile::open(&path).err().unwrap().to_string();
        assert!(header.contains("header length 1000"), "{header}");
    }
}
