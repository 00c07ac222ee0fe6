//! Many segments converted in parallel, each into its own numbered scene folder, with finished scenes skipped.
//!
//! Segment `i` (position in the sorted input list, as in drivestudio's numbered train lists) becomes
//! `<out>/{i:03}/`. It is written into `<out>/{i:03}.partial/`, gets its done marker last, and is then renamed
//! into place, so `<out>/{i:03}/` only ever holds a finished scene: a re-run skips it, and restarts an
//! interrupted one from scratch.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::error::{ConvertError, Result};
use crate::marker::{DoneMarker, read_done};
use crate::waymo::{SegmentSummary, WaymoOptions, convert_segment};

/// One segment and the scene folder it becomes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentJob {
    pub index: usize,
    pub input: PathBuf,
    pub scene: PathBuf,
}

/// What to do when a segment fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailurePolicy {
    /// Start no further segments (those running finish).
    Stop,
    /// Convert every other segment and report the failures at the end.
    KeepGoing,
}

/// What became of one segment.
#[derive(Debug)]
pub enum Outcome {
    Converted(SegmentSummary),
    /// A previous run finished it.
    AlreadyDone(DoneMarker),
    Failed(ConvertError),
    /// Not started because an earlier failure stopped the run.
    NotStarted,
}

/// Hears about the segments as they run (from worker threads).
pub trait Progress: Sync {
    fn started(&self, job: &SegmentJob, total_bytes: u64);
    fn advanced(&self, job: &SegmentJob, bytes_read: u64);
    fn finished(&self, job: &SegmentJob, outcome: &Outcome);
}

/// The Waymo segments at `input` (one `.tfrecord` file, or a folder of them, sorted by name), numbered, with
/// their scene folders under `out`; `scenes` keeps only those numbers.
pub fn waymo_jobs(input: &Path, out: &Path, scenes: Option<&[usize]>) -> Result<Vec<SegmentJob>> {
    let files = if input.is_dir() {
        let entries = std::fs::read_dir(input).map_err(|e| ConvertError::io(input, e))?;
        let mut files: Vec<PathBuf> = entries
            .map(|entry| entry.map(|e| e.path()).map_err(|e| ConvertError::io(input, e)))
            .filter(|path| path.as_ref().map_or(true, |p| p.extension().is_some_and(|ext| ext == "tfrecord")))
            .collect::<Result<_>>()?;
        files.sort();
        files
    } else if input.is_file() {
        vec![input.to_owned()]
    } else {
        return Err(ConvertError::io(
            input,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
        ));
    };
    if files.is_empty() {
        return Err(ConvertError::io(input, std::io::Error::new(std::io::ErrorKind::NotFound, "no .tfrecord files")));
    }
    if let Some(missing) = scenes.and_then(|s| s.iter().find(|&&i| i >= files.len())) {
        return Err(ConvertError::io(
            input,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no segment {missing}: {} segments", files.len()),
            ),
        ));
    }
    Ok(files
        .into_iter()
        .enumerate()
        .filter(|(index, _)| scenes.is_none_or(|s| s.contains(index)))
        .map(|(index, input)| SegmentJob { index, input, scene: out.join(format!("{index:03}")) })
        .collect())
}

/// Converts every job on `workers` threads; the outcomes come back in job order.
pub fn convert_waymo_segments(
    jobs: &[SegmentJob],
    options: &WaymoOptions,
    workers: usize,
    policy: FailurePolicy,
    progress: &dyn Progress,
) -> Result<Vec<Outcome>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers.max(1))
        .build()
        .map_err(|e| ConvertError::io(Path::new("."), std::io::Error::other(e)))?;
    let stopped = AtomicBool::new(false);
    Ok(pool.install(|| {
        jobs.par_iter()
            .with_max_len(1)
            .map(|job| {
                if stopped.load(Ordering::Relaxed) {
                    return Outcome::NotStarted;
                }
                let outcome = convert_one(job, options, progress);
                if matches!(outcome, Outcome::Failed(_)) && policy == FailurePolicy::Stop {
                    stopped.store(true, Ordering::Relaxed);
                }
                progress.finished(job, &outcome);
                outcome
            })
            .collect()
    }))
}

fn convert_one(job: &SegmentJob, options: &WaymoOptions, progress: &dyn Progress) -> Outcome {
    if let Some(marker) = read_done(&job.scene) {
        return Outcome::AlreadyDone(marker);
    }
    match write_scene(job, options, progress) {
        Ok(summary) => Outcome::Converted(summary),
        Err(error) => Outcome::Failed(error),
    }
}

fn write_scene(job: &SegmentJob, options: &WaymoOptions, progress: &dyn Progress) -> Result<SegmentSummary> {
    let total = std::fs::metadata(&job.input).map_err(|e| ConvertError::io(&job.input, e))?.len();
    progress.started(job, total);
    let partial = job.scene.with_extension("partial");
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| ConvertError::io(&partial, e))?;
    }
    let mut summary = convert_segment(&job.input, &partial, options, &|bytes| progress.advanced(job, bytes))?;
    std::fs::rename(&partial, &job.scene).map_err(|e| ConvertError::io(&job.scene, e))?;
    summary.scene = job.scene.clone();
    Ok(summary)
}
