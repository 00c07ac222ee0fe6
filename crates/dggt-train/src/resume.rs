//! What a resumed run must share with its checkpoint, and what it may change.
//!
//! The weights fix the network: a `[model]` section that describes another network (another preset, a pixel
//! skip turned off) is refused, naming every setting that differs with both values, rather than training the
//! checkpoint's network as if the configuration had been applied. Optimiser settings may change between the
//! segments of a run (a lower learning rate to finish, say); the run says which did.
//!
//! What the network sees is fixed too, unless the resume is told otherwise: a change to the input
//! preprocessing (`data.preprocess`: width, patch size, crop) or to the sampler (`[sampler]`: how many inputs and
//! targets a step draws, from which window and cameras) is refused, naming each setting with both values, unless
//! each is allowed by name or by its section ([`AllowedChanges`], `--allow-changed KEY`); an allowed change is
//! reported like an optimiser setting's.
//!
//! Each checkpoint records the sections as configured (`training.json`). Checkpoints of older versions lack
//! it: their network is still compared, field by field of its configuration (`model.json`), and a changed
//! optimiser setting goes unreported. Checkpoints that record the optimiser but not the inputs leave the inputs
//! unchecked; a setting added to a section after a checkpoint was written is not compared.

use std::collections::BTreeSet;
use std::path::Path;

use dggt_model::ModelConfig;
use dggt_run::OptimSection;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::config::{ModelSection, TrainConfig};
use crate::error::Change;
use crate::error::TrainError;

/// What the network sees, as [`ConfiguredSections::inputs`] records it: the preprocessing and the sampler.
const INPUT_SECTIONS: [&str; 2] = ["data", "sampler"];

/// The sections a checkpoint records, in its folder.
pub const TRAINING_FILE: &str = "training.json";

/// `[model]` keys that only matter when a run starts (its starting weights), not to the network resumed.
const STARTING_ONLY: [&str; 2] = ["model.init_checkpoint", "model.init_may_lack"];

/// The `[model]` and `[optim]` sections of a run's configuration, and what its network sees, as each checkpoint
/// records them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ConfiguredSections {
    pub model: ModelSection,
    pub optim: OptimSection,
    /// `{"data": {"preprocess": ..}, "sampler": ..}`; absent in checkpoints of older versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<Value>,
}

impl ConfiguredSections {
    pub fn of(config: &TrainConfig) -> Self {
        Self { model: config.model.clone(), optim: config.optim.clone(), inputs: Some(inputs_of(config)) }
    }
}

/// The settings of `config` that fix what the network sees ([`INPUT_SECTIONS`]).
fn inputs_of(config: &TrainConfig) -> Value {
    serde_json::json!({ "data": { "preprocess": json(&config.data.preprocess) }, "sampler": json(&config.sampler) })
}

/// The settings of what the network sees that a resume may change (`--allow-changed KEY`): each a dotted
/// setting (`data.preprocess.target_width`) or a section holding several (`sampler`, `data.preprocess`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct AllowedChanges {
    keys: Vec<String>,
}

impl AllowedChanges {
    /// No change allowed.
    pub fn none() -> Self {
        Self::default()
    }

    pub fn keys(keys: Vec<String>) -> Self {
        Self { keys }
    }

    /// Whether `setting` is allowed: named, or inside a named section.
    fn allows(&self, setting: &str) -> bool {
        self.keys.iter().any(|key| covers(key, setting))
    }

    /// Warns about each allowed key that matches none of `changes` (a misspelt key allows nothing).
    fn warn_unmatched(&self, changes: &[Change]) {
        for key in &self.keys {
            if !changes.iter().any(|change| covers(key, &change.setting)) {
                tracing::warn!("--allow-changed {key}: no such setting changed since the checkpoint");
            }
        }
    }
}

/// Whether the allowed `key` covers `setting`: the setting itself, or a section holding it.
fn covers(key: &str, setting: &str) -> bool {
    setting == key || setting.strip_prefix(key).is_some_and(|rest| rest.starts_with('.'))
}

/// Checks that `config` describes the network of the checkpoint in `dir` (whose configuration is `stored`) and
/// what it saw, but for the changes `allowed`: an error naming every setting that differs when it does not; the
/// optimiser settings and allowed input settings that changed when it does.
pub fn compare(
    dir: &Path,
    stored: &ModelConfig,
    config: &TrainConfig,
    allowed: &AllowedChanges,
) -> Result<Vec<Change>, TrainError> {
    let recorded = read_sections(dir)?;
    let network = changes("network", &json(stored), &json(&config.model.architecture()));
    if !network.is_empty() {
        let sections = recorded.as_ref().map(|r| changes("model", &json(&r.model), &json(&config.model)));
        let named: Vec<Change> =
            sections.unwrap_or_default().into_iter().filter(|c| !STARTING_ONLY.contains(&c.setting.as_str())).collect();
        let changes = if named.is_empty() { network } else { named };
        return Err(TrainError::ArchitectureChanged { checkpoint: dir.to_path_buf(), changes });
    }
    let Some(recorded) = recorded else {
        tracing::info!(
            checkpoint = %dir.display(),
            "the checkpoint does not record its optimiser settings (an older version): changes are not reported"
        );
        return Ok(Vec::new());
    };
    let mut reported = changes("optim", &json(&recorded.optim), &json(&config.optim));
    let Some(inputs) = &recorded.inputs else {
        tracing::info!(
            checkpoint = %dir.display(),
            "the checkpoint does not record its preprocessing and sampler settings (an older version): changes to \
             them are not checked"
        );
        return Ok(reported);
    };
    let (permitted, refused): (Vec<Change>, Vec<Change>) =
        input_changes(inputs, &inputs_of(config)).into_iter().partition(|change| allowed.allows(&change.setting));
    if !refused.is_empty() {
        return Err(TrainError::InputsChanged { checkpoint: dir.to_path_buf(), changes: refused });
    }
    allowed.warn_unmatched(&permitted);
    reported.extend(permitted);
    Ok(reported)
}

/// Every setting of what the network sees that differs between the checkpoint's record and the configuration,
/// leaving out settings the record lacks (added after it was written).
fn input_changes(recorded: &Value, configured: &Value) -> Vec<Change> {
    INPUT_SECTIONS
        .into_iter()
        .flat_map(|section| {
            let recorded = recorded.get(section).unwrap_or(&Value::Null);
            let configured = configured.get(section).map(|c| pruned_to(c, recorded)).unwrap_or(Value::Null);
            changes(section, recorded, &configured)
        })
        .collect()
}

/// `configured` without the object keys that `recorded` lacks (at any depth).
fn pruned_to(configured: &Value, recorded: &Value) -> Value {
    match (configured, recorded) {
        (Value::Object(configured), Value::Object(recorded)) => Value::Object(
            configured
                .iter()
                .filter_map(|(key, value)| Some((key.clone(), pruned_to(value, recorded.get(key)?))))
                .collect(),
        ),
        _ => configured.clone(),
    }
}

/// The sections recorded in the checkpoint folder `dir`, when it records them.
fn read_sections(dir: &Path) -> Result<Option<ConfiguredSections>, TrainError> {
    let path = dir.join(TRAINING_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let fail = |detail: String| TrainError::Checkpoint { path: path.clone(), detail };
    let bytes = std::fs::read(&path).map_err(|e| fail(e.to_string()))?;
    serde_json::from_slice(&bytes).map(Some).map_err(|e| fail(e.to_string()))
}

fn json(value: &impl Serialize) -> Value {
    serde_json::to_value(value).expect("settings serialise")
}

/// Every leaf that differs between `checkpoint` and `configured`, named under `prefix`.
fn changes(prefix: &str, checkpoint: &Value, configured: &Value) -> Vec<Change> {
    let mut found = Vec::new();
    collect(prefix, checkpoint, configured, &mut found);
    found
}

fn collect(name: &str, checkpoint: &Value, configured: &Value, found: &mut Vec<Change>) {
    match (checkpoint, configured) {
        (Value::Object(a), Value::Object(b)) => {
            let keys: BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            for key in keys {
                let (before, after) = (a.get(key).unwrap_or(&Value::Null), b.get(key).unwrap_or(&Value::Null));
                collect(&format!("{name}.{key}"), before, after, found);
            }
        }
        _ if checkpoint != configured => found.push(Change {
            setting: name.to_string(),
            checkpoint: checkpoint.to_string(),
            configured: configured.to_string(),
        }),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkpoint folder recording `sections`, and the configuration it was written with.
    fn checkpoint(sections: &ConfiguredSections) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(TRAINING_FILE), serde_json::to_vec(sections).unwrap()).unwrap();
        dir
    }

    fn compared(dir: &Path, config: &TrainConfig, allowed: &[&str]) -> Result<Vec<Change>, TrainError> {
        let allowed = AllowedChanges::keys(allowed.iter().map(|key| key.to_string()).collect());
        compare(dir, &config.model.architecture(), config, &allowed)
    }

    #[test]
    fn a_changed_preprocessing_or_sampler_is_refused_naming_the_setting_and_both_values() {
        let config = TrainConfig::default();
        let dir = checkpoint(&ConfiguredSections::of(&config));
        assert_eq!(compared(dir.path(), &config, &[]).unwrap(), [], "the same settings");
        let mut changed = config.clone();
        changed.data.preprocess.target_width = 280;
        changed.data.preprocess.crop_to_square = !config.data.preprocess.crop_to_square;
        changed.sampler.max_inputs += 1;
        let error = compared(dir.path(), &changed, &[]).unwrap_err();
        let TrainError::InputsChanged { changes, .. } = &error else { panic!("{error:?}") };
        let settings: Vec<&str> = changes.iter().map(|change| change.setting.as_str()).collect();
        assert_eq!(settings, ["data.preprocess.crop_to_square", "data.preprocess.target_width", "sampler.max_inputs"]);
        let text = error.to_string();
        assert!(
            text.contains("data.preprocess.target_width is 518 in the checkpoint, 280 in the configuration"),
            "{text}"
        );
        assert!(text.contains("--allow-changed"), "{text}");
    }

    #[test]
    fn an_allowed_change_by_name_or_section_is_reported_and_the_others_still_refused() {
        let config = TrainConfig::default();
        let dir = checkpoint(&ConfiguredSections::of(&config));
        let mut changed = config;
        changed.data.preprocess.target_width = 280;
        changed.sampler.window += 2;
        changed.optim.lr *= 0.5;
        let error = compared(dir.path(), &changed, &["data.preprocess.target_width"]).unwrap_err();
        assert!(
            matches!(&error, TrainError::InputsChanged { changes, .. } if changes.len() == 1 && changes[0].setting == "sampler.window"),
            "{error:?}"
        );
        let reported = compared(dir.path(), &changed, &["data.preprocess.target_width", "sampler"]).unwrap();
        let settings: Vec<&str> = reported.iter().map(|change| change.setting.as_str()).collect();
        assert_eq!(settings, ["optim.lr", "data.preprocess.target_width", "sampler.window"]);
        assert!(compared(dir.path(), &changed, &["data.pre", "sampler"]).is_err(), "a key's prefix is no section");
    }

    #[test]
    fn a_checkpoint_without_recorded_inputs_or_with_fewer_settings_is_compared_on_what_it_records() {
        let config = TrainConfig::default();
        let mut changed = config.clone();
        changed.data.preprocess.target_width = 280;
        let older = ConfiguredSections { inputs: None, ..ConfiguredSections::of(&config) };
        let dir = checkpoint(&older);
        assert_eq!(compared(dir.path(), &changed, &[]).unwrap(), [], "inputs unrecorded: not checked");
        let mut fewer = ConfiguredSections::of(&config);
        let sampler = fewer.inputs.as_mut().unwrap()["sampler"].as_object_mut().unwrap();
        sampler.remove("window");
        let dir = checkpoint(&fewer);
        let mut later = config;
        later.sampler.window += 2;
        assert_eq!(compared(dir.path(), &later, &[]).unwrap(), [], "a setting the record lacks is not compared");
    }
}
