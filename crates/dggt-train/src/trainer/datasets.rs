//! The run's data: the configured datasets indexed (the index cached in the output folder), a single scene's
//! frame range checked, scenes too short for the sampler's window excluded, and the validation scenes picked.

use std::fs;
use std::sync::Arc;

use dggt_data::{DatasetIndex, DatasetSampling, IndexedScene, SceneMix, Split};
use dggt_run::progress::{Visibility, styled_bar};

use crate::config::TrainConfig;
use crate::error::TrainError;

/// The cached scene index in a run's output folder. It is not among the run's own files
/// ([`run_folder::RUN_ENTRIES`]): it is checked against the scenes on every use and rebuilt when stale, and a
/// dry run writes it before any step.
///
/// [`run_folder::RUN_ENTRIES`]: dggt_run::run_folder::RUN_ENTRIES
pub const SCENE_INDEX: &str = "scene-index.json";

/// Indexes the configured datasets (reusing `out_dir/scene-index.json` when still valid), excludes scenes too
/// short for the sampler's window, and picks the validation scenes.
pub(super) fn index_datasets(config: &TrainConfig) -> Result<(DatasetSampling, Vec<IndexedScene>), TrainError> {
    let specs = config.data.dataset_specs(&config.sampler.cameras);
    fs::create_dir_all(&config.run.out_dir)
        .map_err(|source| TrainError::Io { path: config.run.out_dir.clone(), source })?;
    let cache = config.run.out_dir.join(SCENE_INDEX);
    // Drawn only when stderr is a terminal.
    let template = "indexing scenes {elapsed_precise} [{bar:30}] {pos}/{len} ({per_sec}, {eta})";
    let bar = styled_bar(template, Visibility::Shown, None);
    let show = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let mut index = DatasetIndex::load_or_build(&specs, config.run.seed, &cache, &show)?;
    bar.finish_and_clear();
    check_single_scene(config, &index)?;
    index.exclude_shorter_than(config.sampler.window);
    if !index.excluded.is_empty() {
        tracing::warn!(excluded = index.excluded.len(), indexed = index.scenes.len(), "scenes excluded (see the log)");
    }
    let mix = SceneMix::new(&index, config.run.seed)?;
    let mut validation_scenes: Vec<IndexedScene> = index.split(Split::Validation).cloned().collect();
    if validation_scenes.is_empty() {
        validation_scenes.extend(index.split(Split::Train).next().cloned());
    }
    let needed = config.data.validation.inputs.iter().chain(&config.data.validation.targets).max().map(|f| f + 1);
    if let Some(scene) = validation_scenes.iter().find(|s| needed.is_some_and(|n| s.frame_count() < n)) {
        return Err(TrainError::ValidationFrame {
            frame: needed.unwrap_or(0) - 1,
            frame_count: scene.frame_count(),
            scene: scene.root.clone(),
        });
    }
    tracing::info!(
        training = index.split(Split::Train).count(),
        validation = validation_scenes.len(),
        excluded = index.excluded.len(),
        "scenes indexed"
    );
    let sampling =
        DatasetSampling { index: Arc::new(index), mix, sampler: config.sampler.clone(), seed: config.run.seed };
    Ok((sampling, validation_scenes))
}

/// A run on one scene (`data.scene`) uses all of the frames `data.frames` names: a range reaching outside the
/// scene, or a scene that cannot be indexed, is an error rather than a quietly smaller run. (A dataset's
/// `frames` is clipped to each of its scenes, as documented.)
fn check_single_scene(config: &TrainConfig, index: &DatasetIndex) -> Result<(), TrainError> {
    if !config.data.datasets.is_empty() {
        return Ok(());
    }
    if let Some(excluded) = index.excluded.first() {
        return Err(TrainError::SceneExcluded { scene: excluded.root.clone(), reason: excluded.reason.clone() });
    }
    let (Some([start, end]), Some(scene)) = (config.data.frames, index.scenes.first()) else { return Ok(()) };
    // The index clips the range to the scene's frames: each bound it moved lies outside them.
    let (first, last) = (scene.frames.start, scene.frames.end);
    let valid = match (start < first, end > last) {
        (false, false) => return Ok(()),
        (true, false) => format!("a start of at least {first}"),
        (false, true) => format!("an end of at most {last}"),
        (true, true) => format!("a range within [{first}, {last})"),
    };
    Err(TrainError::Setting {
        setting: "data.frames",
        detail: format!("[{start}, {end}) reaches outside the frames of {}: give {valid}", scene.root.display()),
    })
}
