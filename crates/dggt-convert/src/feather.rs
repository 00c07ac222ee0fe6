//! Feather v2 files (the Arrow IPC file format, LZ4-compressed buffers) read as whole tables of named columns,
//! with numeric columns widened to `f64` or `i64` whatever their stored width (Argoverse 2 stores lidar
//! coordinates as float16, sizes as u16, times as i64 nanoseconds).

use std::fs::File;
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float16Type, Float32Type, Float64Type, Int8Type, Int16Type, Int32Type, Int64Type, UInt8Type, UInt16Type, UInt32Type,
};
use arrow_array::{Array, ArrayRef, RecordBatch};
use arrow_ipc::reader::FileReader;

use crate::error::{ConvertError, Result};

/// A whole Feather table.
pub struct Table {
    path: PathBuf,
    batches: Vec<RecordBatch>,
}

impl Table {
    pub fn read(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| ConvertError::io(path, e))?;
        let malformed = |found: String| ConvertError::Table {
            path: path.to_owned(),
            expected: "a Feather v2 (Arrow IPC) file".into(),
            found,
        };
        let reader = FileReader::try_new(file, None).map_err(|e| malformed(e.to_string()))?;
        let batches = reader.collect::<std::result::Result<Vec<_>, _>>().map_err(|e| malformed(e.to_string()))?;
        Ok(Self { path: path.to_owned(), batches })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn rows(&self) -> usize {
        self.batches.iter().map(|b| b.num_rows()).sum()
    }

    fn error(&self, expected: impl Into<String>, found: impl Into<String>) -> ConvertError {
        ConvertError::Table { path: self.path.clone(), expected: expected.into(), found: found.into() }
    }

    fn chunks(&self, name: &str) -> Result<Vec<&ArrayRef>> {
        self.batches
            .iter()
            .map(|batch| batch.column_by_name(name).ok_or_else(|| self.error(format!("a column `{name}`"), "none")))
            .collect()
    }

    /// A numeric column as `f64`, every value finite.
    pub fn f64_column(&self, name: &str) -> Result<Vec<f64>> {
        let mut out = Vec::with_capacity(self.rows());
        for chunk in self.chunks(name)? {
            let before = out.len();
            widen_floats(chunk, &mut out)
                .ok_or_else(|| self.error(format!("column `{name}` of numbers"), format!("{}", chunk.data_type())))?;
            if chunk.null_count() > 0 {
                return Err(
                    self.error(format!("column `{name}` without nulls"), format!("{} nulls", chunk.null_count()))
                );
            }
            if let Some(row) = out[before..].iter().position(|v| !v.is_finite()) {
                return Err(self.error(
                    format!("finite values in `{name}`"),
                    format!("{} in row {}", out[before + row], before + row),
                ));
            }
        }
        Ok(out)
    }

    /// An integer column as `i64`.
    pub fn i64_column(&self, name: &str) -> Result<Vec<i64>> {
        let mut out = Vec::with_capacity(self.rows());
        for chunk in self.chunks(name)? {
            widen_integers(chunk, &mut out)
                .ok_or_else(|| self.error(format!("column `{name}` of integers"), format!("{}", chunk.data_type())))?;
            if chunk.null_count() > 0 {
                return Err(
                    self.error(format!("column `{name}` without nulls"), format!("{} nulls", chunk.null_count()))
                );
            }
        }
        Ok(out)
    }

    /// A string column.
    pub fn string_column(&self, name: &str) -> Result<Vec<String>> {
        let mut out = Vec::with_capacity(self.rows());
        for chunk in self.chunks(name)? {
            let strings: Vec<String> = if let Some(a) = chunk.as_string_opt::<i32>() {
                a.iter().map(|s| s.unwrap_or_default().to_owned()).collect()
            } else if let Some(a) = chunk.as_string_opt::<i64>() {
                a.iter().map(|s| s.unwrap_or_default().to_owned()).collect()
            } else if let Some(a) = chunk.as_string_view_opt() {
                a.iter().map(|s| s.unwrap_or_default().to_owned()).collect()
            } else {
                return Err(self.error(format!("column `{name}` of strings"), format!("{}", chunk.data_type())));
            };
            if chunk.null_count() > 0 {
                return Err(
                    self.error(format!("column `{name}` without nulls"), format!("{} nulls", chunk.null_count()))
                );
            }
            out.extend(strings);
        }
        Ok(out)
    }
}

fn widen_floats(array: &ArrayRef, out: &mut Vec<f64>) -> Option<()> {
    if let Some(a) = array.as_primitive_opt::<Float64Type>() {
        out.extend(a.values().iter().copied());
    } else if let Some(a) = array.as_primitive_opt::<Float32Type>() {
        out.extend(a.values().iter().map(|&v| v as f64));
    } else if let Some(a) = array.as_primitive_opt::<Float16Type>() {
        out.extend(a.values().iter().map(|v| v.to_f64()));
    } else {
        let mut integers = Vec::new();
        widen_integers(array, &mut integers)?;
        out.extend(integers.into_iter().map(|v| v as f64));
    }
    Some(())
}

fn widen_integers(array: &ArrayRef, out: &mut Vec<i64>) -> Option<()> {
    macro_rules! widen {
        ($($t:ty),*) => {
            $(if let Some(a) = array.as_primitive_opt::<$t>() {
                out.extend(a.values().iter().map(|&v| v as i64));
                return Some(());
            })*
        };
    }
    widen!(Int64Type, Int32Type, Int16Type, Int8Type, UInt32Type, UInt16Type, UInt8Type);
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_file_and_a_non_table_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = Table::read(&dir.path().join("gone.feather")).err().unwrap().to_string();
        assert!(missing.contains("gone.feather"), "{missing}");
        let path = dir.path().join("text.feather");
        std::fs::write(&path, "not arrow").unwrap();
        let message = Table::read(&path).err().unwrap().to_string();
        assert!(message.contains("text.feather") && message.contains("Feather v2"), "{message}");
    }
}
