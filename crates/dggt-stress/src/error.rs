//! What ends a stress case, or keeps the suite from starting: an error of the stage the case drove (the
//! geometry, the scene, the network's inference path or the objective), or a preset the suite cannot use.

/// Why a case ended early (its expected outcome when the input was invalid) or the suite could not start.
#[derive(Debug, thiserror::Error)]
pub enum StressError {
    #[error(transparent)]
    Geometry(#[from] dggt_geom::GeomError),
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Inference(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Objective(#[from] dggt_objective::ObjectiveError),
    /// The crafted cases composite over the sky model of the tiny preset.
    #[error("the tiny preset has no sky model, which the crafted cases render")]
    NoSkyModel,
}
