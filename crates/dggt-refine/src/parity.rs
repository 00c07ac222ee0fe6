//! Parity with the reference refiner: a vector folder holds a base model folder (`base/`), a checkpoint
//! (`model_difix.pkl`), `inputs.safetensors` (`image`, `ref_image`, `input_ids`, `prompt_embeds`, `timestep`)
//! and `outputs.safetensors` (every intermediate of the single-view and reference-view modes under `single.`
//! and `ref.`, and `sched.alphas_cumprod`). The refiner is loaded from the folder, run in both modes with the
//! posterior mean, and every reference tensor is compared with the traced one of the same name; one the
//! refiner does not produce fails.
//!
//! Tolerance: `5e-5 * max(1, max|reference|)` on the largest absolute difference.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use burn::tensor::{DType, Device, Tensor, TensorData};

use crate::config::{SchedulerConfig, read_json};
use crate::error::RefineError;
use crate::refiner::{Latent, LoadReport, Refiner, TIMESTEP};
use crate::scheduler::alphas_cumprod;
use crate::trace::Trace;

/// Allowed largest absolute error relative to `max(1, max|reference|)`.
pub const TOLERANCE: f64 = 5e-5;

/// The checkpoint of a vector folder.
pub const CHECKPOINT_FILE: &str = "model_difix.pkl";

/// Whether `dir` is a refiner vector folder (rather than a network one).
pub fn is_refiner_folder(dir: &Path) -> bool {
    dir.join("base").is_dir()
        && dir.join(CHECKPOINT_FILE).is_file()
        && dir.join("inputs.safetensors").is_file()
        && dir.join("outputs.safetensors").is_file()
}

/// The tensors of a safetensors file as stored (f32 and i64 only).
pub fn read_vectors(path: &Path) -> Result<BTreeMap<String, TensorData>, RefineError> {
    let bytes = std::fs::read(path).map_err(|e| RefineError::io(path, e))?;
    let file = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| RefineError::file(path, format!("not a safetensors file: {e}")))?;
    file.tensors()
        .into_iter()
        .map(|(name, view)| {
            let dtype = match view.dtype() {
                safetensors::Dtype::F32 => DType::F32,
                safetensors::Dtype::I64 => DType::I64,
                other => return Err(RefineError::file(path, format!("tensor '{name}' has type {other:?}"))),
            };
            let data = TensorData::from_bytes_vec(view.data().to_vec(), view.shape().to_vec(), dtype);
            Ok((name, data))
        })
        .collect()
}

/// How one reference tensor compares.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    Pass,
    Fail,
    /// Not comparable (not produced, another shape), with the reason: a failure.
    Missing(String),
}

/// One reference tensor and the refiner's error on it.
#[derive(Debug, Clone)]
pub struct ParityRow {
    pub name: String,
    pub shape: Vec<usize>,
    pub max_abs: Option<f64>,
    /// The largest `max_abs` that passes.
    pub tolerance: f64,
    pub status: Status,
}

/// Every compared tensor of one run, and what loading took from where.
#[derive(Debug, Clone)]
pub struct ParityReport {
    pub load: LoadReport,
    pub rows: Vec<ParityRow>,
}

impl ParityReport {
    pub fn passed(&self) -> bool {
        self.failed().next().is_none()
    }

    pub fn failed(&self) -> impl Iterator<Item = &ParityRow> {
        self.rows.iter().filter(|row| row.status != Status::Pass)
    }

    /// One line: how many tensors passed and failed.
    pub fn summary(&self) -> String {
        let failed = self.failed().count();
        format!("{} tensors: {} pass, {failed} fail", self.rows.len(), self.rows.len() - failed)
    }
}

impl fmt::Display for ParityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let width = self.rows.iter().map(|row| row.name.len()).max().unwrap_or(6).max(6);
        writeln!(f, "{:<width$}  {:<16}  {:>11}  {:>11}  status", "tensor", "shape", "max abs err", "tolerance")?;
        for row in &self.rows {
            let error = row.max_abs.map_or_else(|| "-".to_string(), |e| format!("{e:.3e}"));
            let status = match &row.status {
                Status::Pass => "pass".to_string(),
                Status::Fail => "FAIL".to_string(),
                Status::Missing(reason) => format!("FAIL ({reason})"),
            };
            let shape = format!("{:?}", row.shape);
            writeln!(f, "{:<width$}  {shape:<16}  {error:>11}  {:>11.1e}  {status}", row.name, row.tolerance)?;
        }
        Ok(())
    }
}

/// Compares `actual` with `reference` (both f32).
pub fn compare(name: &str, actual: Option<&TensorData>, reference: &TensorData) -> ParityRow {
    let expected = reference.clone().convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
    let max_ref = expected.iter().fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
    let mut row = ParityRow {
        name: name.to_string(),
        shape: reference.shape().to_vec(),
        max_abs: None,
        tolerance: TOLERANCE * max_ref.max(1.0),
        status: Status::Missing("not produced".into()),
    };
    let Some(actual) = actual else { return row };
    if actual.shape() != reference.shape() {
        row.status = Status::Missing(format!("produced with shape {:?}", actual.shape().to_vec()));
        return row;
    }
    let values = actual.clone().convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
    if values.len() != expected.len() {
        row.status = Status::Missing("values not readable as f32".into());
        return row;
    }
    let max_abs = values.iter().zip(&expected).fold(0.0f64, |m, (a, e)| {
        let error = (f64::from(*a) - f64::from(*e)).abs();
        if error.is_nan() { f64::INFINITY } else { m.max(error) }
    });
    row.max_abs = Some(max_abs);
    row.status = if max_abs <= row.tolerance { Status::Pass } else { Status::Fail };
    row
}

/// Loads the refiner of the vector folder `dir` (with `checkpoint`, default `dir/model_difix.pkl`), runs both
/// modes on `device` and compares every reference tensor.
pub fn run_parity(dir: &Path, checkpoint: Option<&Path>, device: &Device) -> Result<ParityReport, RefineError> {
    let inputs = read_vectors(&dir.join("inputs.safetensors"))?;
    let outputs = read_vectors(&dir.join("outputs.safetensors"))?;
    let input = |name: &str| {
        inputs.get(name).ok_or_else(|| RefineError::MissingTensor {
            path: dir.join("inputs.safetensors").display().to_string(),
            name: name.to_string(),
        })
    };
    let tokens =
        input("input_ids")?.try_to_vec::<i64>().map_err(|e| RefineError::Input(format!("input_ids: {e:?}")))?;
    let timestep =
        input("timestep")?.try_to_vec::<i64>().map_err(|e| RefineError::Input(format!("timestep: {e:?}")))?;
    if timestep != [TIMESTEP as i64] {
        return Err(RefineError::Input(format!("the vectors' timestep is {timestep:?}, the refiner's {TIMESTEP}")));
    }
    let checkpoint = checkpoint.map_or_else(|| dir.join(CHECKPOINT_FILE), PathBuf::from);
    let (refiner, load) = Refiner::load(&dir.join("base"), &checkpoint, &tokens, device)?;

    let mut produced = BTreeMap::new();
    produced.insert("prompt_embeds".to_string(), refiner.prompt_embeds().clone().into_data());
    let scheduler_path = dir.join("base/scheduler/scheduler_config.json");
    let alphas = alphas_cumprod(&read_json::<SchedulerConfig>(&scheduler_path)?, &scheduler_path)?;
    let steps = alphas.len();
    produced.insert("sched.alphas_cumprod".to_string(), TensorData::new(alphas, [steps]));
    let image = |name: &str| Ok::<_, RefineError>(Tensor::<4>::from_data(input(name)?.clone(), device));
    for (prefix, reference) in [("single.", None), ("ref.", Some(image("ref_image")?))] {
        let mut trace = Trace::on();
        refiner.refine(image("image")?, reference, Latent::PosteriorMean, &mut trace)?;
        produced.extend(trace.into_records().into_iter().map(|(name, data)| (format!("{prefix}{name}"), data)));
    }

    let prompt = ("prompt_embeds".to_string(), input("prompt_embeds")?.clone());
    let rows = std::iter::once(prompt)
        .chain(outputs)
        .map(|(name, reference)| compare(&name, produced.get(&name), &reference))
        .collect();
    Ok(ParityReport { load, rows })
}
