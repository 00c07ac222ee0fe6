//! Many segments (Waymo TFRecords, Argoverse 2 logs) converted in parallel, each into its own numbered scene
//! folder, with finished scenes skipped.
//!
//! Segment `i` (position in the sorted input list, as in drivestudio's numbered train lists) becomes
//! `<out>/{i:03}/`. It is written into `<out>/{i:03}.partial/`, gets its done marker last (recording what it
//! was converted from and with, [`Provenance`]), and is then renamed into place, so `<out>/{i:03}/` only ever
//! holds a finished scene. A re-run skips a scene whose marker records the same conversion, refuses any other
//! folder in its place unless told to replace it ([`ExistingScenes`]), and restarts an interrupted scene from
//! scratch; a failed scene leaves no partial folder behind. A scene being converted is locked
//! ([`dggt_data::output_lock`]): another command converting the same scene fails on it at once, naming the first.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::depth_flows::DepthFlows;
use crate::error::{ConvertError, Result};
use crate::marker::{DoneMarker, Found, Provenance, Refusal, examine, read_done, source_stamp, write_done};
use crate::masks::DynamicMaskStyle;
use crate::nuscenes::{FrameRate, NuScenesOptions, NuScenesVersion, Tables};
use crate::sky::SkyMasks;
use crate::undistort::Lens;
use crate::waymo::{WaymoOptions, convert_segment};

/// The raw datasets the converters read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Dataset {
    /// Waymo Open Dataset v1: one `Frame` TFRecord per segment; input a `.tfrecord` file or a folder of them.
    Waymo,
    /// Argoverse 2 sensor logs, their images undistorted or as recorded; input one log folder or a split folder
    /// of logs.
    Argoverse2(Lens),
    /// nuScenes: input the data root; the segments are the rows of the version's `scene` table, in table order.
    NuScenes(NuScenesVersion, FrameRate),
}

/// What a segment's progress counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgressUnit {
    Bytes,
    Sweeps,
    Frames,
}

/// What every segment of a run is converted with.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertOptions {
    /// Export camera ids.
    pub cameras: Vec<usize>,
    pub sky_masks: SkyMasks,
    pub depth_flows: DepthFlows,
    pub dynamic_masks: DynamicMaskStyle,
}

impl Dataset {
    /// The dataset and its options, as a done marker records them.
    pub fn describe(&self) -> String {
        match self {
            Self::Waymo => "waymo".into(),
            Self::Argoverse2(Lens::AsRecorded) => "argoverse2".into(),
            Self::Argoverse2(lens) => format!("argoverse2, images {}", lens.name()),
            Self::NuScenes(version, rate) => format!("nuscenes {}, {}", version.folder(), rate.describe()),
        }
    }

    /// The export variant written.
    pub fn variant(&self) -> dggt_data::ExportVariant {
        match self {
            Self::Waymo => dggt_data::ExportVariant::Waymo,
            Self::Argoverse2(_) => dggt_data::ExportVariant::Argoverse2,
            Self::NuScenes(..) => dggt_data::ExportVariant::NuScenes,
        }
    }

    /// Whether `path` in a folder of segments is one (a `.tfrecord` file; a log folder with `calibration/`).
    fn is_segment(&self, path: &Path) -> bool {
        match self {
            Self::Waymo => path.is_file() && path.extension().is_some_and(|ext| ext == "tfrecord"),
            Self::Argoverse2(_) => path.join("calibration").is_dir(),
            Self::NuScenes(..) => false,
        }
    }

    /// What the conversion of every segment needs read first: nuScenes' tables (jobs share the data root).
    fn prepare(&self, jobs: &[SegmentJob]) -> Result<Prepared> {
        Ok(match (self, jobs.first()) {
            (Self::Waymo, _) => Prepared::Waymo,
            (Self::Argoverse2(lens), _) => Prepared::Argoverse2(*lens),
            (Self::NuScenes(version, rate), Some(job)) => {
                Prepared::NuScenes(Box::new(Tables::read(&job.input, version)?), *rate)
            }
            (Self::NuScenes(..), None) => Prepared::Nothing,
        })
    }
}

/// A dataset with what its segments share.
enum Prepared {
    Waymo,
    Argoverse2(Lens),
    NuScenes(Box<Tables>, FrameRate),
    /// No segments to convert.
    Nothing,
}

impl Prepared {
    /// What a segment's progress counts.
    fn progress_unit(&self) -> ProgressUnit {
        match self {
            Self::Waymo | Self::Nothing => ProgressUnit::Bytes,
            Self::Argoverse2(_) => ProgressUnit::Sweeps,
            Self::NuScenes(..) => ProgressUnit::Frames,
        }
    }

    /// How much progress converting `job` takes, in [`Self::progress_unit`]s.
    fn progress_total(&self, job: &SegmentJob) -> u64 {
        match self {
            Self::Waymo | Self::Nothing => std::fs::metadata(&job.input).map_or(0, |m| m.len()),
            Self::Argoverse2(_) => {
                std::fs::read_dir(job.input.join("sensors/lidar")).map_or(0, |entries| entries.count() as u64)
            }
            Self::NuScenes(tables, rate) => {
                tables.scene.rows.get(job.index).map_or(0, |s| rate.frames(s.nbr_samples) as u64)
            }
        }
    }

    fn convert(
        &self,
        job: &SegmentJob,
        scene: &Path,
        options: &ConvertOptions,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Converted> {
        let input = &job.input;
        let summary = match self {
            Self::Waymo => {
                let waymo = WaymoOptions {
                    cameras: options.cameras.clone(),
                    sky_masks: options.sky_masks,
                    depth_flows: options.depth_flows,
                    dynamic_masks: options.dynamic_masks,
                };
                let summary = convert_segment(input, scene, &waymo, progress)?;
                (summary.frames, summary.instances)
            }
            Self::Argoverse2(lens) => {
                let summary = crate::argoverse2::convert_log(input, scene, (options, *lens), progress)?;
                (summary.frames, summary.instances)
            }
            Self::NuScenes(tables, rate) => {
                let nuscenes = NuScenesOptions {
                    cameras: options.cameras.clone(),
                    sky_masks: options.sky_masks,
                    depth_flows: options.depth_flows,
                    dynamic_masks: options.dynamic_masks,
                    rate: *rate,
                };
                let summary = crate::nuscenes::convert_scene(tables, job.index, scene, &nuscenes, progress)?;
                (summary.frames, summary.instances)
            }
            Self::Nothing => (0, 0),
        };
        Ok(Converted { scene: scene.to_owned(), frames: summary.0, instances: summary.1 })
    }
}

/// A converted segment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Converted {
    pub scene: PathBuf,
    pub frames: usize,
    pub instances: usize,
}

/// One segment and the scene folder it becomes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentJob {
    pub index: usize,
    /// The segment's file or folder; for nuScenes, the data root (the segment is row `index` of its scene table).
    pub input: PathBuf,
    /// What progress and failure reports call it: the file or folder name, or the nuScenes scene name.
    pub name: String,
    pub scene: PathBuf,
}

impl SegmentJob {
    /// The segment for messages: its path, and for nuScenes the scene's name after the data root.
    pub fn describe(&self) -> String {
        let file_name = self.input.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if file_name == self.name {
            self.input.display().to_string()
        } else {
            format!("{} {}", self.input.display(), self.name)
        }
    }
}

/// What to do with a scene folder already in place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExistingScenes {
    /// Skip a scene whose marker records the same conversion; refuse anything else.
    Keep,
    /// Convert every scene again, replacing what is in its place once the new scene is complete.
    Replace,
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
    Converted(Converted),
    /// A previous run finished it from the same source with the same options.
    AlreadyDone(Box<DoneMarker>),
    /// Something else is in the scene's place (see [`ExistingScenes`]); it was left as it was.
    Refused(Refusal),
    Failed(ConvertError),
    /// Not started because an earlier failure stopped the run.
    NotStarted,
}

/// Hears about the segments as they run (from worker threads).
pub trait Progress: Sync {
    fn started(&self, job: &SegmentJob, total: u64, unit: ProgressUnit);
    fn advanced(&self, job: &SegmentJob, done: u64);
    fn finished(&self, job: &SegmentJob, outcome: &Outcome);
}

/// The segments of `dataset` at `input` (one segment, or a folder of them sorted by name), numbered, with their
/// scene folders under `out`; `scenes` keeps only those numbers.
pub fn jobs(dataset: &Dataset, input: &Path, out: &Path, scenes: Option<&[usize]>) -> Result<Vec<SegmentJob>> {
    let not_found = |what: String| ConvertError::io(input, std::io::Error::new(std::io::ErrorKind::NotFound, what));
    let file_name = |path: &Path| path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let segments: Vec<(PathBuf, String)> = if let Dataset::NuScenes(version, _) = dataset {
        let names = crate::nuscenes::tables::scene_names(input, version)?;
        names.into_iter().map(|name| (input.to_owned(), name)).collect()
    } else if input.is_file() || dataset.is_segment(input) {
        vec![(input.to_owned(), file_name(input))]
    } else if input.is_dir() {
        let entries = std::fs::read_dir(input).map_err(|e| ConvertError::io(input, e))?;
        let mut segments = Vec::new();
        for entry in entries {
            let path = entry.map_err(|e| ConvertError::io(input, e))?.path();
            if dataset.is_segment(&path) {
                segments.push((path.clone(), file_name(&path)));
            }
        }
        segments.sort();
        segments
    } else {
        return Err(not_found("no such file or folder".into()));
    };
    if segments.is_empty() {
        return Err(not_found(format!("no {} segments", dataset.variant())));
    }
    if let Some(missing) = scenes.and_then(|s| s.iter().find(|&&i| i >= segments.len())) {
        return Err(not_found(format!("no segment {missing}: {} segments", segments.len())));
    }
    Ok(segments
        .into_iter()
        .enumerate()
        .filter(|(index, _)| scenes.is_none_or(|s| s.contains(index)))
        .map(|(index, (input, name))| SegmentJob { index, input, name, scene: out.join(format!("{index:03}")) })
        .collect())
}

/// Converts every job on `workers` threads; the outcomes come back in job order.
pub fn convert_segments(
    dataset: &Dataset,
    jobs: &[SegmentJob],
    options: &ConvertOptions,
    workers: usize,
    policy: FailurePolicy,
    existing: ExistingScenes,
    progress: &dyn Progress,
) -> Result<Vec<Outcome>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers.max(1))
        .build()
        .map_err(|e| ConvertError::io(Path::new("."), std::io::Error::other(e)))?;
    let prepared = dataset.prepare(jobs)?;
    let stopped = AtomicBool::new(false);
    Ok(pool.install(|| {
        jobs.par_iter()
            .with_max_len(1)
            .map(|job| {
                if stopped.load(Ordering::Relaxed) {
                    return Outcome::NotStarted;
                }
                let outcome = convert_one(&prepared, dataset, job, options, existing, progress);
                if matches!(outcome, Outcome::Failed(_) | Outcome::Refused(_)) && policy == FailurePolicy::Stop {
                    stopped.store(true, Ordering::Relaxed);
                }
                progress.finished(job, &outcome);
                outcome
            })
            .collect()
    }))
}

fn convert_one(
    prepared: &Prepared,
    dataset: &Dataset,
    job: &SegmentJob,
    options: &ConvertOptions,
    existing: ExistingScenes,
    progress: &dyn Progress,
) -> Outcome {
    let _lock = match dggt_data::output_lock::OutputLock::acquire(&job.scene, "dggt convert") {
        Ok(lock) => lock,
        Err(error) => return Outcome::Failed(error.into()),
    };
    let provenance = provenance(dataset, job, options);
    if existing == ExistingScenes::Keep {
        match examine(&job.scene, &provenance) {
            Found::Nothing => {}
            Found::Done(marker) => return Outcome::AlreadyDone(marker),
            Found::Refused(refusal) => return Outcome::Refused(refusal),
        }
    }
    match write_scene(prepared, job, options, &provenance, progress) {
        Ok(summary) => Outcome::Converted(summary),
        Err(error) => Outcome::Failed(error),
    }
}

/// What converting `job` with `options` records in its done marker.
fn provenance(dataset: &Dataset, job: &SegmentJob, options: &ConvertOptions) -> Provenance {
    // nuScenes: the data root holds every scene's files, too many to stamp per scene; its tables say what a
    // scene is made of.
    let stamped = match dataset {
        Dataset::NuScenes(version, _) => job.input.join(version.folder()),
        Dataset::Waymo | Dataset::Argoverse2(_) => job.input.clone(),
    };
    Provenance {
        source: std::fs::canonicalize(&job.input).unwrap_or_else(|_| job.input.clone()),
        source_stamp: source_stamp(&stamped),
        segment: job.name.clone(),
        dataset: dataset.describe(),
        cameras: options.cameras.clone(),
        sky_masks: options.sky_masks.name().into(),
        depth_flows: options.depth_flows.name().into(),
        dynamic_masks: options.dynamic_masks.describe(),
        converter: format!("dggt-convert {}", env!("CARGO_PKG_VERSION")),
    }
}

/// Converts `job` into its `.partial` folder, records `provenance` in the marker and moves the scene into
/// place (replacing what was there only now that the new scene is complete). The partial folder is removed
/// when anything fails.
fn write_scene(
    prepared: &Prepared,
    job: &SegmentJob,
    options: &ConvertOptions,
    provenance: &Provenance,
    progress: &dyn Progress,
) -> Result<Converted> {
    progress.started(job, prepared.progress_total(job), prepared.progress_unit());
    let partial = job.scene.with_extension("partial");
    remove_folder(&partial)?;
    let written = prepared
        .convert(job, &partial, options, &|done| progress.advanced(job, done))
        .and_then(|summary| stamp(&partial, provenance).map(|()| summary))
        .and_then(|summary| move_into_place(&partial, &job.scene).map(|()| summary));
    match written {
        Ok(mut summary) => {
            summary.scene = job.scene.clone();
            Ok(summary)
        }
        Err(error) => {
            if let Err(cleanup) = remove_folder(&partial) {
                tracing::warn!(%cleanup, "cannot remove the partial scene");
            }
            Err(error)
        }
    }
}

/// Adds `provenance` to the done marker the converter wrote in `scene`.
fn stamp(scene: &Path, provenance: &Provenance) -> Result<()> {
    let mut marker: DoneMarker = read_done(scene).ok_or_else(|| {
        let missing = std::io::Error::new(std::io::ErrorKind::NotFound, "the converter wrote no done marker");
        ConvertError::io(&scene.join(crate::DONE_MARKER), missing)
    })?;
    marker.provenance = Some(provenance.clone());
    write_done(scene, &marker)
}

/// Renames the finished `partial` folder to `scene`; what was at `scene` is moved aside first and removed
/// after.
fn move_into_place(partial: &Path, scene: &Path) -> Result<()> {
    let replaced = scene.with_extension("replaced");
    let had_scene = scene.exists();
    if had_scene {
        remove_folder(&replaced)?;
        std::fs::rename(scene, &replaced).map_err(|e| ConvertError::io(scene, e))?;
    }
    std::fs::rename(partial, scene).map_err(|e| ConvertError::io(scene, e))?;
    if had_scene {
        remove_folder(&replaced)?;
    }
    Ok(())
}

/// Removes `folder` and everything in it, if it exists.
fn remove_folder(folder: &Path) -> Result<()> {
    match std::fs::remove_dir_all(folder) {
        Err(error) if error.kind() != std::io::ErrorKind::NotFound => Err(ConvertError::io(folder, error)),
        _ => Ok(()),
    }
}
