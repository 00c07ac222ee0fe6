//! Errors of scene synthesis: a configuration the generator does not support, an edit that does not fit the
//! scene, or a failure while writing the export. Invalid arguments are reported here instead of panicking, because they come from the command line.

use crate::object_id::ObjectId;

/// Why a synthetic scene could not be generated or written.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("invalid synthetic-scene configuration: {0}")]
    InvalidConfig(String),
    #[error("no view for frame {frame}, camera {camera}: the scene has {frames} frames and {cameras} cameras")]
    NoSuchView { frame: usize, camera: usize, frames: usize, cameras: usize },
    #[error("no frame {frame}: the scene has {frames} frames")]
    NoSuchFrame { frame: usize, frames: usize },
    #[error("no object {object} to edit: expected an object id in 0..{objects}")]
    UnknownObject { object: ObjectId, objects: usize },
    #[error("object {object} was removed by an earlier edit: expected an object the scene still draws")]
    RemovedObject { object: ObjectId },
    #[error("object {object} is edited twice in different ways: expected one edit per object")]
    ConflictingEdits { object: ObjectId },
    #[error(
        "the move of object {object} has a non-finite {field} ({value}): expected finite offset and pivot (m) and yaw"
    )]
    NonFiniteMove { object: ObjectId, field: &'static str, value: String },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error("synthetic-scene geometry: {0}")]
    Geometry(#[from] dggt_geom::GeomError),
    #[error("cannot serialise {what}: {source}")]
    Json { what: &'static str, source: serde_json::Error },
}

pub type Result<T, E = SynthError> = std::result::Result<T, E>;
