//! Pairs from a reconstruction: a trained DGGT run renders target views at interpolated times (frames that
//! are not among the sample's inputs) from its inputs, exactly as its training and validation do
//! (`dggt_objective::Objective::render` on the sample's [`StepBatch`]); each render is paired with the
//! export's image of that view and, as the reference view, the input view of the same camera nearest in time.
//!
//! The pairs file ([`write_pairs`], [`read_pairs`]) is safetensors: `render`, `target` and `reference`, each
//! `[N, 3, H, W]` float32 RGB in [0, 1], and metadata `views`: a JSON list of `[frame, camera]` per pair
//! (positions in the scene). Many samples' pairs may instead go to a folder of such files, one per sample
//! ([`shard_path`]), written as each sample is rendered so that memory stays bounded and a stopped run resumes;
//! [`crate::pair_files`] reads either, a pair at a time.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dggt_objective::{DepthFlowMaps, StepBatch, ViewTruth, ViewsToRender};
use dggt_scene::nearest_in_time;
use dggt_train::{TrainError, Trainer};

use crate::error::RefineTrainError;
use crate::pair::{Image, Pair};

/// A rendered pair and the view it shows.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedPair {
    pub pair: Pair,
    /// Position in the scene's frames.
    pub frame: usize,
    pub camera: usize,
}

/// The tensors of a pairs file, in this order.
pub(crate) const TENSORS: [&str; 3] = ["render", "target", "reference"];
/// The metadata entry naming each pair's view.
pub(crate) const VIEWS_KEY: &str = "views";

/// Renders the targets of the run's samples `samples` (sample indices, as its steps draw them) with its
/// current weights, on `device` (without autodiff).
pub fn render_pairs(
    trainer: &Trainer,
    samples: impl IntoIterator<Item = u64>,
    device: &Device,
) -> Result<Vec<RenderedPair>, RefineTrainError> {
    let model = trainer.model().clone().valid().fork(device);
    let preprocess = &trainer.config().data.preprocess;
    let mut pairs = Vec::new();
    for index in samples {
        let loaded = trainer.sample(index)?;
        let batch = StepBatch::new(&loaded, &loaded.scene, preprocess, DepthFlowMaps::Skip, device)
            .map_err(TrainError::from)?;
        let (_, views) =
            trainer.objective().render(&model, &batch, ViewsToRender::Targets).map_err(TrainError::from)?;
        for view in views {
            let truth = &batch.targets[view.truth_index];
            let reference = nearest_input(&batch.inputs, truth).ok_or_else(|| {
                RefineTrainError::invalid(
                    format!("sample {index}"),
                    format!("no input view of camera {} to take the reference from", truth.rig_camera),
                )
            })?;
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
    let values = hwc
        .permute([2, 0, 1])
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| RefineTrainError::invalid("render", format!("not readable: {e:?}")))?;
    Ok(Image { height, width, values: values.into_iter().map(|v| v.clamp(0.0, 1.0)).collect() })
}

/// Writes `pairs` (all of one size, each with a reference) to `path` (see the module's doc), atomically.
pub fn write_pairs(pairs: &[RenderedPair], path: &Path) -> Result<(), RefineTrainError> {
    let invalid = |detail: String| RefineTrainError::invalid(path.display().to_string(), detail);
    let first = pairs.first().ok_or_else(|| invalid("no pairs to write".into()))?;
    let (height, width) = (first.pair.render.height, first.pair.render.width);
    let mut columns: [Vec<u8>; 3] = Default::default();
    for rendered in pairs {
        let Pair { render, target, reference } = &rendered.pair;
        let reference =
            reference.as_ref().ok_or_else(|| invalid(format!("frame {} has no reference", rendered.frame)))?;
        for (column, image) in columns.iter_mut().zip([render, target, reference]) {
            if (image.height, image.width) != (height, width) {
                return Err(invalid(format!(
                    "frame {}: {}x{} among {height}x{width} images",
                    rendered.frame, image.height, image.width
                )));
            }
            column.extend(image.values.iter().flat_map(|v| v.to_le_bytes()));
        }
    }
    let shape = vec![pairs.len(), 3, height, width];
    let views = TENSORS.iter().zip(&columns).map(|(name, bytes)| {
        let view =
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes).expect("sizes agree");
        (name.to_string(), view)
    });
    let frames: Vec<[usize; 2]> = pairs.iter().map(|p| [p.frame, p.camera]).collect();
    let metadata = HashMap::from([(VIEWS_KEY.to_string(), serde_json::to_string(&frames).expect("numbers serialise"))]);
    let file = safetensors::serialize(views, Some(metadata)).map_err(|e| invalid(e.to_string()))?;
    dggt_data::io::write_atomically(path, &file).map_err(|e| invalid(e.to_string()))
}

/// The file of sample `sample`'s pairs in a folder of pair shards.
pub fn shard_path(dir: &Path, sample: u64) -> PathBuf {
    dir.join(format!("sample-{sample:06}.safetensors"))
}
