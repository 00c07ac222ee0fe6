//! A run's metric records: `metrics.jsonl` in its output folder, one JSON object a line with its `kind`
//! (`train` for a step, `validation` for a validation pass) and its `step`. A resumed run first drops the
//! records it is about to write again, so the file reads as that of an uninterrupted run.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::RunError;

/// What a record reports, its `kind`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RecordKind {
    /// One optimiser step.
    Train,
    /// One validation pass, after the step it names.
    Validation,
}

/// A record as written: its kind, then its own fields.
#[derive(Serialize)]
struct Line<'a, T> {
    kind: RecordKind,
    #[serde(flatten)]
    record: &'a T,
}

/// The metrics file of a run, open for appending.
pub struct MetricsLog {
    path: PathBuf,
    file: File,
}

impl MetricsLog {
    /// Opens `path` (creating its folder) for a run that continues at step `step`: the records of steps at or
    /// after it are dropped first ([`truncate_metrics`]).
    pub fn continuing_at(path: &Path, step: u64) -> Result<Self, RunError> {
        let io = |source| RunError::Io { path: path.into(), source };
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(|source| RunError::Io { path: parent.into(), source })?;
        }
        truncate_metrics(path, step)?;
        let file = fs::OpenOptions::new().create(true).append(true).open(path).map_err(io)?;
        Ok(Self { path: path.to_path_buf(), file })
    }

    /// Appends `record` as one line, its `kind` first.
    pub fn append(&mut self, kind: RecordKind, record: &impl Serialize) -> Result<(), RunError> {
        let line = serde_json::to_string(&Line { kind, record }).expect("records serialise");
        writeln!(self.file, "{line}").map_err(|source| RunError::Io { path: self.path.clone(), source })
    }
}

/// Drops the records (JSON lines with a `step`) of steps at or after `step` from a metrics file, keeping the
/// validation of step `step` itself (it validated the weights a resume starts from): a resumed run writes the
/// others again.
pub fn truncate_metrics(path: &Path, step: u64) -> Result<(), RunError> {
    if !path.exists() {
        return Ok(());
    }
    let text = fs::read_to_string(path).map_err(|source| RunError::Io { path: path.into(), source })?;
    let kept: String = text
        .lines()
        .filter(|line| {
            serde_json::from_str::<serde_json::Value>(line).ok().and_then(|v| v["step"].as_u64()).is_some_and(|s| {
                match step {
                    0 => false,
                    _ => s < step || (s == step && line.contains("\"validation\"")),
                }
            })
        })
        .map(|line| format!("{line}\n"))
        .collect();
    dggt_data::io::write_atomically(path, kept.as_bytes())
        .map_err(|e| RunError::Metrics { path: path.into(), detail: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Step {
        step: u64,
        loss: f64,
    }

    #[test]
    fn a_resumed_log_keeps_earlier_steps_and_the_validation_of_its_first_step() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run").join("metrics.jsonl");
        let mut log = MetricsLog::continuing_at(&path, 0).unwrap();
        for step in 0..3 {
            log.append(RecordKind::Train, &Step { step, loss: 0.5 }).unwrap();
            log.append(RecordKind::Validation, &Step { step: step + 1, loss: 0.25 }).unwrap();
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("{\"kind\":\"train\",\"step\":0,\"loss\":0.5}\n"), "{text}");
        drop(log);
        MetricsLog::continuing_at(&path, 2).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let kept: Vec<&str> = text.lines().collect();
        assert_eq!(kept.len(), 4, "steps 0 and 1 with the validations after them: {kept:?}");
        assert!(kept[3].contains("\"validation\"") && kept[3].contains("\"step\":2"), "{kept:?}");
        MetricsLog::continuing_at(&path, 0).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "", "a fresh start keeps nothing");
    }
}
