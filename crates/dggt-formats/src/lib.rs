//! The files a reconstruction is delivered in, each written so that existing tools open it, and read back so
//! that tests can check what was written.
//!
//! One module per format, each naming its conventions in its types and docs:
//! - [`ply`]: Gaussians in the INRIA 3DGS binary PLY layout (pre-activation values, SH degree 0);
//! - [`colmap`]: COLMAP text cameras (`PINHOLE`) and images (camera-from-world `qw qx qy qz tx ty tz`);
//! - [`nerfstudio`]: `transforms.json` (camera-to-world in OpenGL axes);
//! - [`cameras_json`]: this project's camera file, which states its convention inside;
//! - [`depth`]: float32 `.npy` depth maps and 16-bit PNGs with their scale in a JSON beside them;
//! - [`masks`]: 8-bit PNG probability maps and binary masks; [`images`]: RGB PNG frames.
//!
//! Every reader treats its file as untrusted and returns an [`FormatError`] naming it.

pub mod cameras_json;
pub mod colmap;
pub mod depth;
mod error;
pub mod images;
pub mod masks;
pub mod nerfstudio;
pub mod ply;

pub use error::FormatError;

/// Writes `bytes` to `path` atomically, creating the folder ([`dggt_data::io::write_atomically`]).
pub(crate) fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<(), FormatError> {
    Ok(dggt_data::io::write_atomically(path, bytes)?)
}

/// Encodes `image` as PNG and writes it to `path` ([`write_file`]).
pub(crate) fn write_png(path: &std::path::Path, image: &image::DynamicImage) -> Result<(), FormatError> {
    let mut encoded = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut encoded, image::ImageFormat::Png)
        .map_err(|e| FormatError::invalid(path, format!("encoding PNG: {e}")))?;
    write_file(path, &encoded.into_inner())
}

pub(crate) fn read_file(path: &std::path::Path) -> Result<Vec<u8>, FormatError> {
    std::fs::read(path).map_err(|e| FormatError::io(path, e))
}
