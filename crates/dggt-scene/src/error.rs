//! Errors of scene assembly: they name the input at fault.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("{tensor}: expected shape {expected}, got {actual:?}")]
    Shape { tensor: &'static str, expected: String, actual: Vec<usize> },
    #[error("{what}: {detail}")]
    Invalid { what: &'static str, detail: String },
    #[error("camera {camera} has no input view to interpolate its pose from")]
    NoInputForCamera { camera: usize },
    #[error(transparent)]
    Geom(#[from] dggt_geom::GeomError),
    #[error("rendering {what}: {source}")]
    Render { what: String, source: dggt_splat::SplatError },
}
