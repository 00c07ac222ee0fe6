//! float32 `.npy` arrays (C order), as scene exports store depth and scene flow.

use std::path::Path;

use crate::error::{DataError, Result};

/// A dense float32 array with its shape.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// Reads a float32 C-order `.npy` file, checking that its data matches its shape.
pub fn read_npy_f32(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let file = npyz::NpyFile::new(&bytes[..]).map_err(|e| DataError::malformed(path, "a .npy file", e.to_string()))?;
    if file.order() != npyz::Order::C {
        return Err(DataError::malformed(path, "C (row-major) order", "Fortran order"));
    }
    let dtype = file.dtype();
    if dtype != <f32 as npyz::AutoSerialize>::default_dtype() {
        return Err(DataError::malformed(path, "dtype '<f4' (little-endian float32)", dtype.descr()));
    }
    let shape: Vec<usize> = file.shape().iter().map(|&d| d as usize).collect();
    let data: Vec<f32> =
        file.into_vec().map_err(|e| DataError::malformed(path, "complete float32 data", e.to_string()))?;
    if data.len() != shape.iter().product::<usize>() {
        return Err(DataError::malformed(
            path,
            format!("{} values for shape {shape:?}", shape.iter().product::<usize>()),
            format!("{}", data.len()),
        ));
    }
    Ok(NpyArray { shape, data })
}

/// Writes a float32 C-order `.npy` file atomically.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    use npyz::WriterBuilder;
    if data.len() != shape.iter().product::<usize>() {
        return Err(DataError::Config(format!(
            "cannot write {}: {} values do not fill shape {shape:?}",
            path.display(),
            data.len()
        )));
    }
    let shape_u64: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape_u64)
        .writer(&mut bytes)
        .begin_nd()
        .map_err(|e| DataError::io(path, e))?;
    writer.extend(data.iter().copied()).map_err(|e| DataError::io(path, e))?;
    writer.finish().map_err(|e| DataError::io(path, e))?;
    crate::io::write_atomically(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        let data: Vec<f32> = (0..24).map(|v| v as f32 * 0.5).collect();
        write_npy_f32(&path, &[2, 3, 4], &data).unwrap();
        let back = read_npy_f32(&path).unwrap();
        assert_eq!(back.shape, vec![2, 3, 4]);
        assert_eq!(back.data, data);
        assert!(write_npy_f32(&path, &[5], &data).is_err());
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 8]).unwrap();
        let err = read_npy_f32(&path).unwrap_err().to_string();
        assert!(err.contains("a.npy"), "{err}");
    }
}
