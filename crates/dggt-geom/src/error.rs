//! Errors raised when geometric input is not what a convention requires.

/// A geometric value that cannot be used: non-finite numbers, a matrix that is not a rigid transform, a
/// degenerate quaternion or camera. Each variant says which value and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeomError {
    #[error("{what} contains a non-finite value (NaN or infinity)")]
    NonFinite { what: &'static str },
    #[error("{what} is not a rigid transform: {detail}")]
    NotRigid { what: &'static str, detail: String },
    #[error("{what} is a zero quaternion; a rotation needs a non-zero norm")]
    ZeroQuaternion { what: &'static str },
    #[error("invalid pinhole intrinsics: {detail}")]
    InvalidIntrinsics { detail: String },
    #[error("invalid image size {width}x{height}: both sides must be positive")]
    InvalidImageSize { width: u32, height: u32 },
    #[error("depth map has {actual} values, expected {expected} for a {width}x{height} image")]
    DepthSizeMismatch { actual: usize, expected: usize, width: u32, height: u32 },
}
