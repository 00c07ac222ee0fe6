//! The flow head's hyper-parameters, read from TOML or JSON (unknown keys refused, missing keys defaulted) and
//! validated before a head is built.

use serde::{Deserialize, Serialize};

/// Widths, neighbourhood and iteration counts of a [`FlowHead`](crate::FlowHead). Stored flat (the widths beside
/// the shape's fields, unknown keys refused), as configurations and checkpoints have always written it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "FlatConfig", into = "FlatConfig")]
pub struct FlowHeadConfig {
    /// Channels of each input feature scale, in the order [`crate::sample_features`] concatenates them (fixed by
    /// the network the head reads). Default: four scales of 256 channels, the width of the DPT head's fused maps.
    pub feature_widths: Vec<usize>,
    /// Everything else: the head's own choices.
    pub shape: FlowHeadShape,
}

/// The stored form of a [`FlowHeadConfig`].
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct FlatConfig {
    feature_widths: Vec<usize>,
    hidden: usize,
    heads: usize,
    neighbours: usize,
    iterations: usize,
    chunk: usize,
    inputs: HeadInputs,
}

impl Default for FlatConfig {
    fn default() -> Self {
        FlowHeadConfig::default().into()
    }
}

impl From<FlatConfig> for FlowHeadConfig {
    fn from(flat: FlatConfig) -> Self {
        let FlatConfig { feature_widths, hidden, heads, neighbours, iterations, chunk, inputs } = flat;
        Self { feature_widths, shape: FlowHeadShape { hidden, heads, neighbours, iterations, chunk, inputs } }
    }
}

impl From<FlowHeadConfig> for FlatConfig {
    fn from(config: FlowHeadConfig) -> Self {
        let FlowHeadShape { hidden, heads, neighbours, iterations, chunk, inputs } = config.shape;
        Self { feature_widths: config.feature_widths, hidden, heads, neighbours, iterations, chunk, inputs }
    }
}

/// A [`FlowHead`](crate::FlowHead)'s own choices, whatever features it reads (a training configuration's
/// `[model.flow]`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowHeadShape {
    /// Width of the head's tokens.
    pub hidden: usize,
    /// Attention heads; each attends over `hidden / heads` channels.
    pub heads: usize,
    /// Target neighbours each query attends to (fewer when the target cloud is smaller).
    pub neighbours: usize,
    /// Refinement iterations: each one searches the neighbours again around the moved query.
    pub iterations: usize,
    /// Queries processed together: memory grows with `chunk x neighbours x hidden`.
    pub chunk: usize,
    /// What the tokens are made of (the image features can be left out, to measure what they buy).
    pub inputs: HeadInputs,
}

/// What a [`FlowHead`](crate::FlowHead)'s tokens carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadInputs {
    /// Each point's image features, and each neighbour's offset from the query (the paper's head).
    #[default]
    FeaturesAndOffsets,
    /// The offsets alone: the head matches geometry only (its feature projection sees zeros).
    OffsetsOnly,
}

impl Default for FlowHeadShape {
    fn default() -> Self {
        Self {
            hidden: 64,
            heads: 4,
            neighbours: 16,
            iterations: 3,
            chunk: 8192,
            inputs: HeadInputs::FeaturesAndOffsets,
        }
    }
}

impl Default for FlowHeadConfig {
    fn default() -> Self {
        Self { feature_widths: vec![256; 4], shape: FlowHeadShape::default() }
    }
}

/// What is wrong with a [`FlowHeadConfig`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    #[error("feature_widths is empty: the flow head needs at least one feature scale")]
    NoFeatureScales,
    #[error("feature_widths[{index}] is 0: every feature scale needs channels")]
    EmptyFeatureScale { index: usize },
    #[error("{field} is 0: it must be positive")]
    Zero { field: &'static str },
    #[error("hidden width {hidden} is not a multiple of the {heads} attention heads")]
    HeadsDoNotDivideHidden { hidden: usize, heads: usize },
}

impl FlowHeadConfig {
    /// Checks every field; the first problem found is returned.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.feature_widths.is_empty() {
            return Err(ConfigError::NoFeatureScales);
        }
        if let Some(index) = self.feature_widths.iter().position(|&w| w == 0) {
            return Err(ConfigError::EmptyFeatureScale { index });
        }
        let shape = &self.shape;
        let counts = [
            ("hidden", shape.hidden),
            ("heads", shape.heads),
            ("neighbours", shape.neighbours),
            ("iterations", shape.iterations),
            ("chunk", shape.chunk),
        ];
        if let Some((field, _)) = counts.iter().find(|(_, value)| *value == 0) {
            return Err(ConfigError::Zero { field });
        }
        if !shape.hidden.is_multiple_of(shape.heads) {
            return Err(ConfigError::HeadsDoNotDivideHidden { hidden: shape.hidden, heads: shape.heads });
        }
        Ok(())
    }

    /// Channels of one point's features: the sum of [`Self::feature_widths`].
    pub fn feature_width(&self) -> usize {
        self.feature_widths.iter().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_valid_and_missing_keys_take_it() {
        let config: FlowHeadConfig = serde_json::from_str(r#"{"hidden": 32, "inputs": "offsets_only"}"#).unwrap();
        let shape = FlowHeadShape { hidden: 32, inputs: HeadInputs::OffsetsOnly, ..FlowHeadShape::default() };
        assert_eq!(config, FlowHeadConfig { shape, ..FlowHeadConfig::default() });
        assert_eq!(FlowHeadConfig::default().validate(), Ok(()));
        assert_eq!(FlowHeadConfig::default().feature_width(), 1024);
    }

    #[test]
    fn unknown_keys_are_refused() {
        let error = serde_json::from_str::<FlowHeadConfig>(r#"{"hiden": 32}"#).unwrap_err();
        assert!(error.to_string().contains("hiden"), "{error}");
        let error = serde_json::from_str::<FlowHeadShape>(r#"{"iteration": 2}"#).unwrap_err();
        assert!(error.to_string().contains("iteration"), "{error}");
        // A checkpoint's stored form, written before `inputs` existed, reads back; the stored form is flat.
        let stored = r#"{"feature_widths": [16, 32], "hidden": 64, "heads": 4, "neighbours": 16, "iterations": 3, "chunk": 8192}"#;
        let config: FlowHeadConfig = serde_json::from_str(stored).unwrap();
        assert_eq!(config, FlowHeadConfig { feature_widths: vec![16, 32], ..FlowHeadConfig::default() });
        let written = serde_json::to_value(&config).unwrap();
        assert_eq!(written["iterations"], 3);
        assert_eq!(written["inputs"], "features_and_offsets");
    }

    #[test]
    fn each_bad_field_is_named() {
        let bad = |edit: fn(&mut FlowHeadConfig)| {
            let mut config = FlowHeadConfig::default();
            edit(&mut config);
            config.validate().unwrap_err()
        };
        assert_eq!(bad(|c| c.feature_widths.clear()), ConfigError::NoFeatureScales);
        assert_eq!(bad(|c| c.feature_widths[2] = 0), ConfigError::EmptyFeatureScale { index: 2 });
        assert_eq!(bad(|c| c.shape.neighbours = 0), ConfigError::Zero { field: "neighbours" });
        assert_eq!(bad(|c| c.shape.iterations = 0), ConfigError::Zero { field: "iterations" });
        assert_eq!(bad(|c| c.shape.chunk = 0), ConfigError::Zero { field: "chunk" });
        assert_eq!(bad(|c| c.shape.heads = 0), ConfigError::Zero { field: "heads" });
        assert_eq!(bad(|c| c.shape.heads = 5), ConfigError::HeadsDoNotDivideHidden { hidden: 64, heads: 5 });
    }
}
