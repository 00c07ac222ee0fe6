//! Parity of the refiner with the reference (diffusers and peft): a vector folder holds a base model folder
//! (`base/`), a checkpoint (`model_difix.pkl`), `inputs.safetensors` (`image`, `ref_image`, `input_ids`,
//! `prompt_embeds`, `timestep`) and `outputs.safetensors` (every intermediate of the single-view and
//! reference-view modes under `single.` and `ref.`, and `sched.alphas_cumprod`). The refiner is loaded from the
//! folder, run in both modes with the posterior mean, and every reference tensor is compared with the traced
//! one of the same name; one the refiner does not produce fails.
//!
//! Tolerance: [`crate::tolerance::REFINER`] on the largest absolute difference, computed in `f64`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dggt_model::safetensors_file::{SafetensorsError, SafetensorsFile};
use dggt_refine::config::{SchedulerConfig, read_json};
use dggt_refine::refiner::{Latent, LoadReport, Refiner, TIMESTEP};
use dggt_refine::scheduler::alphas_cumprod;
use dggt_refine::trace::Trace;

use crate::error::ParityError;
use crate::report::{ParityReport, ParityRow, Status};
use crate::tolerance::REFINER;

/// The checkpoint of a vector folder.
pub const CHECKPOINT_FILE: &str = "model_difix.pkl";

/// Whether `dir` is a refiner vector folder (rather than a network one).
pub fn is_refiner_folder(dir: &Path) -> bool {
    dir.join("base").is_dir()
        && dir.join(CHECKPOINT_FILE).is_file()
        && dir.join("inputs.safetensors").is_file()
        && dir.join("outputs.safetensors").is_file()
}

/// The tensors of a safetensors file as stored, by name.
pub fn read_vectors(path: &Path) -> Result<BTreeMap<String, TensorData>, SafetensorsError> {
    SafetensorsFile::open(path)?.read_all_data()
}

/// One run of the refiner's vectors: what loading took from where, and the comparison.
#[derive(Debug, Clone)]
pub struct RefinerRun {
    pub load: LoadReport,
    pub report: ParityReport,
}

/// Compares `actual` with `reference` (both read as f32); `None` when the refiner did not produce the tensor.
pub fn compare(name: &str, actual: Option<&TensorData>, reference: &TensorData) -> ParityRow {
    let shape = reference.shape().to_vec();
    let expected = reference.clone().convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
    let Some(actual) = actual else {
        return ParityRow::not_compared(name, &shape, Status::NotProduced("not produced".into()));
    };
    if actual.shape() != reference.shape() {
        return ParityRow::not_compared(name, &shape, Status::ShapeMismatch(actual.shape().to_vec()));
    }
    let values = actual.clone().convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
    if values.len() != expected.len() {
        return ParityRow::not_compared(name, &shape, Status::NotProduced("values not readable as f32".into()));
    }
    let max_reference = expected.iter().fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
    let max_abs = values.iter().zip(&expected).fold(0.0f64, |m, (a, e)| {
        let error = (f64::from(*a) - f64::from(*e)).abs();
        if error.is_nan() { f64::INFINITY } else { m.max(error) }
    });
    let tolerance = REFINER.allowed(max_reference);
    ParityRow {
        name: name.to_string(),
        shape,
        max_abs: Some(max_abs),
        max_rel: Some(max_abs / max_reference.max(f64::MIN_POSITIVE)),
        tolerance: Some(tolerance),
        status: if max_abs <= tolerance { Status::Pass } else { Status::OutOfTolerance },
        note: None,
    }
}

/// The inputs of a refiner vector folder.
struct RefinerInputs {
    dir: PathBuf,
    tensors: BTreeMap<String, TensorData>,
}

impl RefinerInputs {
    fn get(&self, name: &'static str) -> Result<&TensorData, ParityError> {
        self.tensors.get(name).ok_or_else(|| ParityError::MissingInput { dir: self.dir.clone(), name })
    }

    /// The integer input `name`.
    fn integers(&self, name: &'static str) -> Result<Vec<i64>, ParityError> {
        let data = self.get(name)?;
        data.clone().convert::<i64>().try_into_vec::<i64>().map_err(|e| ParityError::BadInput {
            dir: self.dir.clone(),
            name,
            expected: "integers".into(),
            found: format!("{:?} ({e:?})", data.dtype()),
        })
    }

    fn image(&self, name: &'static str, device: &Device) -> Result<Tensor<4>, ParityError> {
        Ok(Tensor::from_data(self.get(name)?.clone(), device))
    }
}

/// Loads the refiner of the vector folder `dir` (with `checkpoint`, default `dir/model_difix.pkl`), runs both
/// modes on `device` and compares every reference tensor, the prompt embedding first.
pub fn run_parity(dir: &Path, checkpoint: Option<&Path>, device: &Device) -> Result<RefinerRun, ParityError> {
    let inputs = RefinerInputs { dir: dir.to_path_buf(), tensors: read_vectors(&dir.join("inputs.safetensors"))? };
    let outputs = read_vectors(&dir.join("outputs.safetensors"))?;
    let tokens = inputs.integers("input_ids")?;
    let timestep = inputs.integers("timestep")?;
    if timestep != [TIMESTEP as i64] {
        let (expected, found) = (format!("[{TIMESTEP}] (the refiner's)"), format!("{timestep:?}"));
        return Err(ParityError::BadInput { dir: dir.to_path_buf(), name: "timestep", expected, found });
    }
    let checkpoint = checkpoint.map_or_else(|| dir.join(CHECKPOINT_FILE), PathBuf::from);
    let (refiner, load) = Refiner::load(&dir.join("base"), &checkpoint, &tokens, device)?;

    let mut produced = BTreeMap::new();
    produced.insert("prompt_embeds".to_string(), refiner.prompt_embeds().clone().into_data());
    let scheduler_path = dir.join("base/scheduler/scheduler_config.json");
    let alphas = alphas_cumprod(&read_json::<SchedulerConfig>(&scheduler_path)?, &scheduler_path)?;
    let steps = alphas.len();
    produced.insert("sched.alphas_cumprod".to_string(), TensorData::new(alphas, [steps]));
    for (prefix, reference) in [("single.", None), ("ref.", Some(inputs.image("ref_image", device)?))] {
        let mut trace = Trace::on();
        refiner.refine(inputs.image("image", device)?, reference, Latent::PosteriorMean, &mut trace)?;
        produced.extend(trace.into_records().into_iter().map(|(name, data)| (format!("{prefix}{name}"), data)));
    }

    let prompt = ("prompt_embeds".to_string(), inputs.get("prompt_embeds")?.clone());
    let rows = std::iter::once(prompt)
        .chain(outputs)
        .map(|(name, reference)| compare(&name, produced.get(&name), &reference))
        .collect();
    Ok(RefinerRun { load, report: ParityReport { rows } })
}
