//! What a resumed run must share with its checkpoint, and what it may change.
//!
//! The weights fix the network: a `[model]` section that describes another network (another preset, a pixel
//! skip turned off) is refused, naming every setting that differs with both values, rather than training the
//! checkpoint's network as if the configuration had been applied. Optimiser settings may change between the
//! segments of a run (a lower learning rate to finish, say); the run says which did.
//!
//! Each checkpoint records the sections as configured (`training.json`). Checkpoints of older versions lack
//! it: their network is still compared, field by field of its configuration (`model.json`), and a changed
//! optimiser setting goes unreported.

use std::collections::BTreeSet;
use std::path::Path;

use dggt_model::ModelConfig;
use dggt_run::OptimSection;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::config::{ModelSection, TrainConfig};
use crate::error::Change;
use crate::error::TrainError;

/// The sections a checkpoint records, in its folder.
pub const TRAINING_FILE: &str = "training.json";

/// `[model]` keys that only matter when a run starts (its starting weights), not to the network resumed.
const STARTING_ONLY: [&str; 2] = ["model.init_checkpoint", "model.init_may_lack"];

/// The `[model]` and `[optim]` sections of a run's configuration, as each checkpoint records them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ConfiguredSections {
    pub model: ModelSection,
    pub optim: OptimSection,
}

impl ConfiguredSections {
    pub fn of(config: &TrainConfig) -> Self {
        Self { model: config.model.clone(), optim: config.optim.clone() }
    }
}

/// Checks that `config` describes the network of the checkpoint in `dir` (whose configuration is `stored`):
/// an error naming every setting that differs when it does not; the optimiser settings that changed when it
/// does.
pub fn compare(dir: &Path, stored: &ModelConfig, config: &TrainConfig) -> Result<Vec<Change>, TrainError> {
    let recorded = read_sections(dir)?;
    let network = changes("network", &json(stored), &json(&config.model.architecture()));
    if !network.is_empty() {
        let sections = recorded.as_ref().map(|r| changes("model", &json(&r.model), &json(&config.model)));
        let named: Vec<Change> =
            sections.unwrap_or_default().into_iter().filter(|c| !STARTING_ONLY.contains(&c.setting.as_str())).collect();
        let changes = if named.is_empty() { network } else { named };
        return Err(TrainError::ArchitectureChanged { checkpoint: dir.to_path_buf(), changes });
    }
    Ok(match recorded {
        Some(recorded) => changes("optim", &json(&recorded.optim), &json(&config.optim)),
        None => {
            tracing::info!(
                checkpoint = %dir.display(),
                "the checkpoint does not record its optimiser settings (an older version): changes are not reported"
            );
            Vec::new()
        }
    })
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
