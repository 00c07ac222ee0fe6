//! Pairs from a reconstruction: a trained DGGT network renders target views at interpolated times (frames
//! that are not among the sample's inputs) from its inputs, exactly as its training and validation do
//! (`dggt_objective::Objective::render` on the sample's [`StepBatch`]); each render is paired with the
//! export's image of that view and, as the reference view, the input view of the same camera nearest in time.
//! The pairs are written and read back by [`crate::pair_files`].

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_data::{DatasetSampling, DecodedViews, LoaderOptions, Preprocess};
use dggt_model::Dggt;
use dggt_model::host::host_f32;
use dggt_objective::{DepthFlowMaps, Objective, StepBatch, ViewTruth, ViewsToRender};
use dggt_scene::nearest_in_time;

use crate::error::RefineTrainError;
use crate::pair::{Image, Pair, RenderedPair};

/// What pairs are rendered from: a reconstruction run's network, the objective that renders its views, and
/// the samples its training draws with the preprocessing it trained with (a DGGT trainer holds all four).
#[derive(Clone, Copy)]
pub struct Reconstruction<'a> {
    pub model: &'a Dggt,
    pub objective: &'a Objective,
    pub sampling: &'a DatasetSampling,
    pub preprocess: &'a Preprocess,
}

/// Renders the targets of the run's samples `samples` (sample indices, as its steps draw them) with its
/// network, on `device` (without autodiff).
pub fn render_pairs(
    run: Reconstruction<'_>,
    samples: impl IntoIterator<Item = u64>,
    device: &Device,
) -> Result<Vec<RenderedPair>, RefineTrainError> {
    let model = run.model.clone().valid().fork(device);
    let mut pairs = Vec::new();
    let decoded = DecodedViews::new(LoaderOptions::DEFAULT_DECODED_CACHE_BYTES);
    for index in samples {
        let loaded = run.sampling.load(run.preprocess, index, &decoded)?;
        let batch = StepBatch::new(&loaded, &loaded.scene, run.preprocess, DepthFlowMaps::Skip, device)?;
        let (_, views) = run.objective.render(&model, &batch, ViewsToRender::Targets)?;
        for view in views {
            let truth = &batch.targets[view.truth_index];
            let reference = nearest_input(&batch.inputs, truth)
                .ok_or(RefineTrainError::NoReference { sample: index, camera: truth.rig_camera })?;
            pairs.push(RenderedPair {
                pair: Pair {
                    render: host_image(view.rgb)?,
                    target: host_image(truth.image.clone())?,
                    reference: Some(host_image(reference.image.clone())?),
                },
                frame: truth.frame,
                camera: truth.rig_camera,
            });
        }
    }
    Ok(pairs)
}

/// The input view of `target`'s camera nearest to it in time (the earlier of two as near).
fn nearest_input<'a>(inputs: &'a [ViewTruth], target: &ViewTruth) -> Option<&'a ViewTruth> {
    let candidates = inputs.iter().map(|v| (v.rig_camera, v.time));
    nearest_in_time(candidates, target.rig_camera, target.time).map(|position| &inputs[position])
}

/// `[H, W, 3]` in [0, 1] to a host image.
fn host_image(hwc: Tensor<3>) -> Result<Image, RefineTrainError> {
    let [height, width, _] = hwc.dims();
    let values = host_f32(hwc.permute([2, 0, 1]), "render: image")?;
    Ok(Image { height, width, values: values.into_iter().map(|v| v.clamp(0.0, 1.0)).collect() })
}
