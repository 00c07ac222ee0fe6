//! Whitespace-separated numeric text files: the matrices and calibration vectors of scene exports and KITTI.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use crate::error::{DataError, Result};

/// Parses every whitespace-separated number of `text`; `path` only names the file in errors.
pub fn parse_numbers(path: &Path, text: &str) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|token| {
            let value: f64 = token
                .parse()
                .map_err(|_| DataError::malformed(path, "whitespace-separated numbers", format!("token {token:?}")))?;
            if !value.is_finite() {
                return Err(DataError::malformed(path, "finite numbers", token.to_string()));
            }
            Ok(value)
        })
        .collect()
}

/// Reads a file holding exactly `count` finite numbers.
pub fn read_numbers(path: &Path, count: usize) -> Result<Vec<f64>> {
    let text = fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let values = parse_numbers(path, &text)?;
    if values.len() != count {
        return Err(DataError::malformed(path, format!("{count} numbers"), format!("{} numbers", values.len())));
    }
    Ok(values)
}

/// Reads a row-major `R x C` matrix stored as whitespace-separated numbers.
pub fn read_matrix<const R: usize, const C: usize>(path: &Path) -> Result<[[f64; C]; R]> {
    let flat = read_numbers(path, R * C)?;
    Ok(std::array::from_fn(|i| std::array::from_fn(|j| flat[i * C + j])))
}

/// Formats rows of numbers, one row per line, with full `f64` round-trip precision.
pub fn format_rows<const C: usize>(rows: &[[f64; C]]) -> String {
    let mut out = String::new();
    for row in rows {
        let line: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
        let _ = writeln!(out, "{}", line.join(" "));
    }
    out
}

/// Writes rows of numbers, one row per line.
pub fn write_rows<const C: usize>(path: &Path, rows: &[[f64; C]]) -> Result<()> {
    crate::io::write_atomically(path, format_rows(rows).as_bytes())
}
