//! Why the port could not produce its value of a reference output. Such an output is reported as not compared
//! ([`crate::report::Status::NotProduced`]), with this as the reason.

use crate::network::release_render::RenderError;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReproduceError {
    /// A part of the network the vectors' configuration does not build (`gs_head`, `sky_model`, ...).
    #[error("the network has no {0}")]
    NoPart(&'static str),
    /// A head the forward pass did not run.
    #[error("the forward pass did not run the {0}")]
    NotRun(&'static str),
    /// An index past the end of a list of layers or iterations.
    #[error("the port has {available} {what}, not {}", index + 1)]
    NoEntry { what: &'static str, available: usize, index: usize },
    /// An input the output needs that the vectors lack or hold in another form.
    #[error("{input}: {problem}")]
    Input { input: &'static str, problem: String },
    #[error("decoding the pose: {0}")]
    PoseDecoding(dggt_geom::GeomError),
    #[error("unprojecting the depth: {0}")]
    Unprojection(dggt_geom::GeomError),
    #[error(transparent)]
    Render(#[from] RenderError),
}
