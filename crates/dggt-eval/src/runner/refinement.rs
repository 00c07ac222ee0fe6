//! The diffusion refiner of an evaluation, when one is asked: loaded once, given its reference view for a
//! target, and run over a render, whose refined image is scored beside the render.

use burn::tensor::Device;
use dggt_geom::ImageSize;
use dggt_refine::{ReferenceView, Refiner, frame_from_interleaved, frame_to_interleaved};
use dggt_scene::TargetView;

use super::forward::ForwardScene;
use super::setup::{EvalOptions, SceneContext};
use super::views::nearest_input;
use crate::error::EvalError;

/// The refiner of the options' spec, loaded on `device`; none without a spec.
pub(super) fn load_refiner(options: &EvalOptions, device: &Device) -> Result<Option<Refiner>, EvalError> {
    match &options.refine {
        Some(spec) => {
            let (refiner, _) = spec.load(device).map_err(|source| EvalError::Refine {
                doing: format!("loading refiner {}", spec.describe()),
                source,
            })?;
            Ok(Some(refiner))
        }
        None => Ok(None),
    }
}

/// The refiner's reference view for `target` (interleaved), as the spec asks: none, or the input view of the
/// target's camera nearest in time.
pub(super) fn reference_view(
    forward: &ForwardScene,
    target: &TargetView,
    context: &SceneContext<'_>,
) -> Result<Option<Vec<f32>>, EvalError> {
    let spec = context.options.refine.as_ref().expect("a refiner comes from its spec");
    match spec.reference {
        ReferenceView::None => Ok(None),
        ReferenceView::NearestInput => {
            let position =
                nearest_input(forward, target).ok_or(EvalError::NoReferenceView { camera: target.rig_camera })?;
            Ok(Some(forward.input_images[position].interleaved()))
        }
    }
}

/// The render `rgb` (interleaved, clamped) after the refiner, attending to `reference` (interleaved) when
/// given; interleaved.
pub(super) fn refine_render(
    refiner: &Refiner,
    rgb: &[f32],
    reference: Option<Vec<f32>>,
    size: ImageSize,
    context: &SceneContext<'_>,
) -> Result<Vec<f32>, EvalError> {
    let refine_error = |source| EvalError::Refine { doing: "refining a render".into(), source };
    let spec = context.options.refine.as_ref().expect("a refiner comes from its spec");
    let (h, w) = (size.height as usize, size.width as usize);
    let frame = frame_from_interleaved(rgb, h, w, context.device).map_err(refine_error)?;
    let reference =
        reference.map(|rgb| frame_from_interleaved(&rgb, h, w, context.device)).transpose().map_err(refine_error)?;
    let refined = refiner.refine_frames(frame, reference, spec.latent, 1, |_| ()).map_err(refine_error)?;
    frame_to_interleaved(&refined, 0).map_err(refine_error)
}
