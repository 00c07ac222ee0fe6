//! The flow head's hyper-parameters, read from TOML or JSON (unknown keys refused, missing keys defaulted) and
//! validated before a head is built.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::head::FlowHead;

/// Widths, neighbourhood and iteration counts of a [`FlowHead`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowHeadConfig {
    /// Channels of each input feature scale, in the order [`crate::sample_features`] concatenates them. Default:
    /// four scales of 256 channels, the width of the DPT head's fused maps.
    pub feature_widths: Vec<usize>,
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
}

impl Default for FlowHeadConfig {
    fn default() -> Self {
        Self { feature_widths: vec![256; 4], hidden: 64, heads: 4, neighbours: 16, iterations: 3, chunk: 8192 }
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
        let counts = [
            ("hidden", self.hidden),
            ("heads", self.heads),
            ("neighbours", self.neighbours),
            ("iterations", self.iterations),
            ("chunk", self.chunk),
        ];
        if let Some((field, _)) = counts.iter().find(|(_, value)| *value == 0) {
            return Err(ConfigError::Zero { field });
        }
        if !self.hidden.is_multiple_of(self.heads) {
            return Err(ConfigError::HeadsDoNotDivideHidden { hidden: self.hidden, heads: self.heads });
        }
        Ok(())
    }

    /// Channels of one point's features: the sum of [`Self::feature_widths`].
    pub fn feature_width(&self) -> usize {
        self.feature_widths.iter().sum()
    }

    /// A fresh head on `device`: random weights, except the last layer of the update, which is zero, so that
    /// the head predicts no motion until it is trained.
    pub fn init(&self, device: &Device) -> Result<FlowHead, ConfigError> {
        self.validate()?;
        Ok(FlowHead::new(self, device))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_valid_and_missing_keys_take_it() {
        let config: FlowHeadConfig = serde_json::from_str(r#"{"hidden": 32}"#).unwrap();
        assert_eq!(config, FlowHeadConfig { hidden: 32, ..FlowHeadConfig::default() });
        assert_eq!(FlowHeadConfig::default().validate(), Ok(()));
        assert_eq!(FlowHeadConfig::default().feature_width(), 1024);
    }

    #[test]
    fn unknown_keys_are_refused() {
        let error = serde_json::from_str::<FlowHeadConfig>(r#"{"hiden": 32}"#).unwrap_err();
        assert!(error.to_string().contains("hiden"), "{error}");
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
        assert_eq!(bad(|c| c.neighbours = 0), ConfigError::Zero { field: "neighbours" });
        assert_eq!(bad(|c| c.iterations = 0), ConfigError::Zero { field: "iterations" });
        assert_eq!(bad(|c| c.chunk = 0), ConfigError::Zero { field: "chunk" });
        assert_eq!(bad(|c| c.heads = 0), ConfigError::Zero { field: "heads" });
        assert_eq!(bad(|c| c.heads = 5), ConfigError::HeadsDoNotDivideHidden { hidden: 64, heads: 5 });
        assert!(FlowHeadConfig { heads: 5, ..FlowHeadConfig::default() }.init(&Device::flex()).is_err());
    }
}
