//! Errors of scene assembly: they name the input at fault.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("{tensor}: expected shape {expected}, got {actual:?}")]
    Shape { tensor: &'static str, expected: String, actual: Vec<usize> },
    #[error("{what}: {detail}")]
    Invalid { what: &'static str, detail: String },
    /// A network output holds NaN or infinity: the sample cannot be assembled (a trainer skips it).
    #[error("{tensor}: non-finite value {value} at view {view}, pixel {pixel}")]
    NonFinite { tensor: &'static str, value: f32, view: usize, pixel: usize },
    #[error("camera {camera} has no input view to interpolate its pose from")]
    NoInputForCamera { camera: usize },
    #[error(transparent)]
    Geom(#[from] dggt_geom::GeomError),
    #[error("rendering {what}: {source}")]
    Render { what: String, source: dggt_splat::SplatError },
}
