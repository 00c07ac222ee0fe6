//! Errors of scene assembly: they name the input at fault.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("{tensor}: expected shape {expected}, got {actual:?}")]
    Shape { tensor: &'static str, expected: String, actual: Vec<usize> },
    /// A camera's pose or intrinsics hold NaN or infinity.
    #[error("camera: non-finite pose or intrinsics")]
    NonFiniteCamera,
    /// A timeline needs at least one input frame.
    #[error("timeline: no input frames")]
    NoInputFrames,
    /// A time (scene time, or frames per unit of it) is NaN or infinite.
    #[error("{what}: {value} is not finite")]
    NonFiniteTime { what: &'static str, value: f64 },
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    /// A network output holds NaN or infinity: the sample cannot be assembled (a trainer skips it).
    #[error("{tensor}: non-finite value {value} at view {view}, pixel {pixel}")]
    NonFinite { tensor: &'static str, value: f32, view: usize, pixel: usize },
    #[error("camera {camera} has no input view to interpolate its pose from")]
    NoInputForCamera { camera: usize },
    #[error(transparent)]
    Geom(#[from] dggt_geom::GeomError),
    #[error("finding the moving objects: {0}")]
    Instances(#[from] dggt_instances::ShapeError),
    /// A saved scene that cannot be written or read back.
    #[error("{}: {detail}", path.display())]
    File { path: std::path::PathBuf, detail: String },
    #[error("learnt scene flow: {0}")]
    Flow(#[from] dggt_flow_head::FlowError),
    #[error("learnt scene flow features: {0}")]
    FlowFeatures(#[from] dggt_flow_head::SampleError),
    /// The learnt motion was asked of a scene whose network has no flow head.
    #[error("render.dynamic_motion = \"learnt\" needs a network with a flow head (model.flow_head)")]
    NoFlowHead,
    #[error("rendering {what}: {source}")]
    Render { what: String, source: dggt_splat::SplatError },
}
