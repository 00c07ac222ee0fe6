//! The scene index of a run: every scene folder of the configured datasets, found and checked once, with what
//! sampling needs (layout, frame range, cameras, split), so that no training step scans a folder.
//!
//! Indexing reads metadata only: folder listings, the calibration and pose text files of the first frame and
//! the header of one image per camera; never a whole image. A scene whose files are broken (a pose file
//! missing in the middle, a camera without intrinsics, an image missing for some frame) is excluded with the
//! reason naming the file, and the run reports how many were.
//!
//! The index is cached as JSON ([`DatasetIndex::load_or_build`]) and reused while the dataset specifications
//! and every scene folder's modification time are unchanged.

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::export::frame_indices;
use crate::layout::ExportLayout;
use crate::open::{LogLayout, open_scene_as};
use crate::random::splitmix64;
use crate::scene::{Scene, SceneSource};

/// One dataset of a run: where its scenes are (exactly one of `root`, `list`, `globs`), how to read them, how
/// often to draw them and which are held out for validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetSpec {
    /// A name for reports; the root's or list's file name when absent.
    pub name: Option<String>,
    /// A folder of scene folders, or one scene folder.
    pub root: Option<PathBuf>,
    /// A text file listing scene folders, one per line, relative to the file's folder (and inside it: no `..`,
    /// no absolute path, no symbolic link leading out); `#` starts a comment.
    pub list: Option<PathBuf>,
    /// Glob patterns matching scene folders.
    pub globs: Vec<String>,
    pub layout: LogLayout,
    /// Camera ids read from every scene, in this order; empty reads every camera.
    pub cameras: Vec<usize>,
    /// Log frames `[start, end)` used from every scene (clipped to what each has); all when absent.
    pub frames: Option<[usize; 2]>,
    /// Relative sampling weight: an epoch draws about `weight x scenes` of this dataset's training scenes.
    pub weight: f64,
    pub held_out: HeldOut,
}

/// Which scenes of a dataset are held out of training for validation.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeldOut {
    /// Every scene trains.
    #[default]
    None,
    /// This share of the scenes, chosen by a hash of the run seed and the scene's name, so that adding scenes
    /// does not reshuffle the others.
    Fraction(f64),
    /// The scenes named (folder names) in this list file, one per line.
    List(PathBuf),
    /// These scene folder names.
    Scenes(Vec<String>),
}

impl Default for DatasetSpec {
    fn default() -> Self {
        Self {
            name: None,
            root: None,
            list: None,
            globs: Vec::new(),
            layout: LogLayout::Detect,
            cameras: Vec::new(),
            frames: None,
            weight: 1.0,
            held_out: HeldOut::None,
        }
    }
}

impl DatasetSpec {
    /// The name used in reports.
    pub fn display_name(&self) -> String {
        let from_path = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned());
        self.name
            .clone()
            .or_else(|| self.root.as_deref().and_then(from_path))
            .or_else(|| self.list.as_deref().and_then(from_path))
            .unwrap_or_else(|| "dataset".into())
    }

    /// Checks what no type can: one source, a usable weight and held-out share.
    pub fn validate(&self) -> Result<()> {
        let sources = [self.root.is_some(), self.list.is_some(), !self.globs.is_empty()];
        if sources.iter().filter(|&&s| s).count() != 1 {
            return Err(self.config_error("give exactly one of root, list and globs"));
        }
        if !(self.weight.is_finite() && self.weight > 0.0) {
            return Err(self.config_error(format!("weight must be positive, got {}", self.weight)));
        }
        if let Some([start, end]) = self.frames
            && start >= end
        {
            return Err(self.config_error(format!("frames [{start}, {end}) is empty")));
        }
        if let HeldOut::Fraction(share) = self.held_out
            && !(0.0..1.0).contains(&share)
        {
            return Err(self.config_error(format!("held_out fraction must lie in [0, 1), got {share}")));
        }
        Ok(())
    }

    fn config_error(&self, detail: impl std::fmt::Display) -> DataError {
        DataError::Config(format!("dataset {}: {detail}", self.display_name()))
    }

    /// Resolves relative paths against `base` (the configuration file's folder).
    pub fn resolve_paths(&mut self, base: &Path) {
        for path in [&mut self.root, &mut self.list].into_iter().flatten() {
            if path.is_relative() {
                *path = base.join(&*path);
            }
        }
        if let HeldOut::List(path) = &mut self.held_out
            && path.is_relative()
        {
            *path = base.join(&*path);
        }
        for pattern in &mut self.globs {
            if Path::new(pattern).is_relative() {
                *pattern = base.join(&*pattern).to_string_lossy().into_owned();
            }
        }
    }

    /// The scene folders of this dataset, sorted.
    pub fn scene_folders(&self) -> Result<Vec<PathBuf>> {
        let mut folders = if let Some(root) = &self.root {
            if is_scene_folder(root) { vec![root.clone()] } else { subfolders(root)? }
        } else if let Some(list) = &self.list {
            listed_folders(list)?
        } else {
            self.glob_folders()?
        };
        folders.sort();
        folders.dedup();
        Ok(folders)
    }

    fn glob_folders(&self) -> Result<Vec<PathBuf>> {
        let mut folders = Vec::new();
        for pattern in &self.globs {
            let paths = glob::glob(pattern).map_err(|e| self.config_error(format!("glob {pattern:?}: {e}")))?;
            folders.extend(paths.flatten().filter(|p| p.is_dir()));
        }
        Ok(folders)
    }

    /// The folder names held out of training.
    fn held_out_names(&self, folders: &[PathBuf], seed: u64) -> Result<BTreeSet<String>> {
        let names = folders.iter().map(|f| folder_name(f));
        Ok(match &self.held_out {
            HeldOut::None => BTreeSet::new(),
            HeldOut::Scenes(names) => names.iter().cloned().collect(),
            HeldOut::List(path) => read_list(path)?.into_iter().collect(),
            HeldOut::Fraction(share) => {
                let count = (share * folders.len() as f64).round() as usize;
                let mut ranked: Vec<(u64, String)> = names.map(|name| (name_hash(seed, &name), name)).collect();
                ranked.sort();
                ranked.into_iter().take(count).map(|(_, name)| name).collect()
            }
        })
    }
}

fn is_scene_folder(path: &Path) -> bool {
    path.join("images").is_dir() || path.join("poses.txt").is_file()
}

fn subfolders(root: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(root).map_err(|e| DataError::io(root, e))?;
    Ok(entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect())
}

fn read_list(path: &Path) -> Result<Vec<String>> {
    Ok(numbered_entries(path)?.into_iter().map(|(_, entry)| entry).collect())
}

/// The entries of a list file with their line numbers (from 1): each line up to a `#`, trimmed, when not empty.
fn numbered_entries(path: &Path) -> Result<Vec<(usize, String)>> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    Ok(text
        .lines()
        .enumerate()
        .map(|(index, line)| (index + 1, line.split('#').next().unwrap_or("").trim()))
        .filter(|(_, line)| !line.is_empty())
        .map(|(number, line)| (number, line.to_owned()))
        .collect())
}

/// The scene folders the list file `list` names, each inside the list's folder ([`crate::confined`]); one that
/// leads out is an error naming the file and the line.
fn listed_folders(list: &Path) -> Result<Vec<PathBuf>> {
    let base = list.parent().filter(|parent| !parent.as_os_str().is_empty()).unwrap_or(Path::new("."));
    numbered_entries(list)?
        .into_iter()
        .map(|(number, entry)| {
            crate::confined::confined_path(base, Path::new(&entry)).map_err(|escape| {
                DataError::malformed(
                    list,
                    format!("line {number}: a scene folder inside the list's folder"),
                    escape.to_string(),
                )
            })
        })
        .collect()
}

fn folder_name(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

fn name_hash(seed: u64, name: &str) -> u64 {
    name.bytes().fold(splitmix64(seed), |hash, byte| splitmix64(hash ^ byte as u64))
}

/// Whether a scene trains or validates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    Train,
    Validation,
}

/// One indexed scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndexedScene {
    /// Position of its dataset in the configuration.
    pub dataset: usize,
    /// `dataset/folder`.
    pub name: String,
    pub root: PathBuf,
    /// The resolved layout (never [`LogLayout::Detect`]).
    pub layout: LogLayout,
    /// Log frame indices `[first, end)`; every frame in it has a pose and an image per camera.
    pub frames: Range<usize>,
    /// Camera ids, in the configured order.
    pub cameras: Vec<usize>,
    pub split: Split,
    /// The folder's modification time (seconds since the epoch), for cache reuse.
    pub modified_s: u64,
}

impl IndexedScene {
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Opens the log frames `frames` (positions `0..frame_count()` of this scene) with the indexed cameras;
    /// the scene is named as the index names it (`dataset/folder`).
    pub fn open(&self, frames: Range<usize>) -> Result<Scene> {
        let range = self.frames.start + frames.start..self.frames.start + frames.end;
        let mut scene = open_scene_as(&self.root, self.layout, Some(range), Some(self.cameras.clone()))?;
        scene.name = self.name.clone();
        Ok(scene)
    }
}

/// A scene left out of the index, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExcludedScene {
    pub root: PathBuf,
    pub reason: String,
}

/// Every usable scene of a run's datasets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetIndex {
    pub specs: Vec<DatasetSpec>,
    pub seed: u64,
    pub scenes: Vec<IndexedScene>,
    pub excluded: Vec<ExcludedScene>,
}

impl DatasetIndex {
    /// Indexes every scene folder of `specs` (in parallel), calling `progress(done, total)` as scenes finish.
    pub fn build(specs: &[DatasetSpec], seed: u64, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<Self> {
        let mut jobs = Vec::new();
        for (dataset, spec) in specs.iter().enumerate() {
            spec.validate()?;
            let folders = spec.scene_folders()?;
            if folders.is_empty() {
                return Err(spec.config_error("no scene folders found"));
            }
            let held_out = spec.held_out_names(&folders, seed)?;
            jobs.extend(folders.into_iter().map(|root| {
                let split = if held_out.contains(&folder_name(&root)) { Split::Validation } else { Split::Train };
                (dataset, root, split)
            }));
        }
        let total = jobs.len();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let outcomes: Vec<std::result::Result<IndexedScene, ExcludedScene>> = jobs
            .into_par_iter()
            .map(|(dataset, root, split)| {
                let outcome = index_scene(&specs[dataset], dataset, &root, split)
                    .map_err(|error| ExcludedScene { root, reason: error.to_string() });
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
                outcome
            })
            .collect();
        let (mut scenes, mut excluded) = (Vec::new(), Vec::new());
        for outcome in outcomes {
            match outcome {
                Ok(scene) => scenes.push(scene),
                Err(scene) => {
                    tracing::warn!(scene = %scene.root.display(), reason = %scene.reason, "scene excluded");
                    excluded.push(scene);
                }
            }
        }
        Ok(Self { specs: specs.to_vec(), seed, scenes, excluded })
    }

    /// The index cached at `cache` when it was built from the same specifications and seed and no scene folder
    /// changed since; otherwise a new one, written to `cache` atomically.
    pub fn load_or_build(
        specs: &[DatasetSpec],
        seed: u64,
        cache: &Path,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Self> {
        if let Some(cached) = Self::read_cache(cache)
            && cached.specs == specs
            && cached.seed == seed
            && cached.is_fresh()
        {
            tracing::info!(cache = %cache.display(), scenes = cached.scenes.len(), "scene index reused");
            return Ok(cached);
        }
        let index = Self::build(specs, seed, progress)?;
        let json = serde_json::to_vec(&index).map_err(|e| DataError::Config(format!("scene index: {e}")))?;
        crate::io::write_atomically(cache, &json)?;
        Ok(index)
    }

    fn read_cache(path: &Path) -> Option<Self> {
        serde_json::from_slice(&std::fs::read(path).ok()?).ok()
    }

    /// Whether every folder the index saw is as it was: the same folders, unmodified.
    fn is_fresh(&self) -> bool {
        let folders: Option<BTreeSet<PathBuf>> = self
            .specs
            .iter()
            .map(|spec| spec.scene_folders().ok())
            .collect::<Option<Vec<_>>>()
            .map(|lists| lists.into_iter().flatten().collect());
        let seen: BTreeSet<PathBuf> =
            self.scenes.iter().map(|s| s.root.clone()).chain(self.excluded.iter().map(|s| s.root.clone())).collect();
        folders.is_some_and(|folders| folders == seen)
            && self.scenes.iter().all(|scene| modified_s(&scene.root).is_some_and(|m| m == scene.modified_s))
    }

    /// Moves training scenes with fewer than `frames` frames to the excluded ones (a sampling window must fit).
    pub fn exclude_shorter_than(&mut self, frames: usize) {
        let (kept, short): (Vec<_>, Vec<_>) =
            self.scenes.drain(..).partition(|s| s.split != Split::Train || s.frame_count() >= frames);
        self.scenes = kept;
        for scene in short {
            let reason = format!("{} frames, fewer than the sampler's window of {frames}", scene.frame_count());
            tracing::warn!(scene = %scene.root.display(), %reason, "scene excluded");
            self.excluded.push(ExcludedScene { root: scene.root, reason });
        }
    }

    /// The scenes of `split`.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &IndexedScene> {
        self.scenes.iter().filter(move |s| s.split == split)
    }
}

fn modified_s(path: &Path) -> Option<u64> {
    let time = std::fs::metadata(path).ok()?.modified().ok()?;
    Some(time.duration_since(UNIX_EPOCH).ok()?.as_secs())
}

/// Indexes one scene folder: its layout, frames and cameras, checked on the first frame's files and on the
/// image listing.
fn index_scene(spec: &DatasetSpec, dataset: usize, root: &Path, split: Split) -> Result<IndexedScene> {
    let cameras = (!spec.cameras.is_empty()).then(|| spec.cameras.clone());
    let probe = open_scene_as(root, spec.layout, Some(0..1).filter(|_| !is_kitti(root)), cameras)?;
    let (layout, frames) = match probe.source {
        SceneSource::Kitti => (LogLayout::Kitti, 0..probe.frames.len()),
        SceneSource::Export(variant) => (LogLayout::from(variant), contiguous_frames(root, variant)?),
    };
    let frames = match spec.frames {
        Some([start, end]) => frames.start.max(start)..frames.end.min(end),
        None => frames,
    };
    if frames.is_empty() {
        return Err(DataError::malformed(root, format!("frames in {:?}", spec.frames), "none"));
    }
    let cameras: Vec<usize> = probe.cameras.iter().map(|c| c.id).collect();
    if layout != LogLayout::Kitti {
        check_images(root, &frames, &cameras)?;
    }
    Ok(IndexedScene {
        dataset,
        name: format!("{}/{}", spec.display_name(), folder_name(root)),
        root: root.to_owned(),
        layout: if spec.layout == LogLayout::Synthetic { LogLayout::Synthetic } else { layout },
        frames,
        cameras,
        split,
        modified_s: modified_s(root).unwrap_or(0),
    })
}

fn is_kitti(root: &Path) -> bool {
    root.join("poses.txt").is_file()
}

/// The export's frame indices, which must be consecutive.
fn contiguous_frames(root: &Path, variant: crate::variant::ExportVariant) -> Result<Range<usize>> {
    let (indices, folder) = frame_indices(root, variant)?;
    let (first, last) = (indices[0], indices[indices.len() - 1]);
    if last - first + 1 != indices.len() {
        let missing = (first..=last).find(|t| indices.binary_search(t).is_err()).unwrap_or(first);
        return Err(DataError::malformed(
            &folder,
            format!("consecutive frames {first}..={last}"),
            format!("no frame {missing}"),
        ));
    }
    Ok(first..last + 1)
}

/// Every (frame, camera) has its image, by one listing of `images/`.
fn check_images(root: &Path, frames: &Range<usize>, cameras: &[usize]) -> Result<()> {
    let folder = root.join("images");
    let entries = std::fs::read_dir(&folder).map_err(|e| DataError::io(&folder, e))?;
    let present: BTreeSet<std::ffi::OsString> = entries.flatten().map(|e| e.file_name()).collect();
    let layout = ExportLayout::new(root);
    for frame in frames.clone() {
        for &camera in cameras {
            let image = layout.image(frame, camera);
            if !image.file_name().is_some_and(|name| present.contains(name)) {
                return Err(DataError::malformed(&image, "a camera image", "missing"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A list file beside the scene folders `a` and `b`, with `lines` after a comment and a listed `a`.
    fn list_with(dir: &Path, lines: &str) -> DatasetSpec {
        for scene in ["a", "b"] {
            std::fs::create_dir_all(dir.join("scenes").join(scene).join("images")).unwrap();
        }
        let list = dir.join("scenes/list.txt");
        std::fs::write(&list, format!("# training scenes\na  # the first\n\n{lines}")).unwrap();
        DatasetSpec { list: Some(list), ..DatasetSpec::default() }
    }

    #[test]
    fn a_list_names_scene_folders_relative_to_its_folder() {
        let dir = tempfile::tempdir().unwrap();
        let folders = list_with(dir.path(), "./b\n").scene_folders().unwrap();
        assert_eq!(folders, [dir.path().join("scenes/a"), dir.path().join("scenes/./b")]);
    }

    #[test]
    fn a_listed_folder_leading_out_of_the_lists_folder_is_refused_naming_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("elsewhere/images")).unwrap();
        let absolute = dir.path().join("elsewhere").display().to_string();
        for (line, why) in [("../elsewhere", "`..` component"), (absolute.as_str(), "is absolute")] {
            let spec = list_with(dir.path(), &format!("{line}\n"));
            let error = spec.scene_folders().unwrap_err().to_string();
            assert!(error.contains("list.txt") && error.contains("line 4") && error.contains(why), "{error}");
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(dir.path().join("elsewhere"), dir.path().join("scenes/linked")).unwrap();
            let error = list_with(dir.path(), "linked\n").scene_folders().unwrap_err().to_string();
            assert!(error.contains("line 4") && error.contains("leads outside"), "{error}");
        }
    }
}
