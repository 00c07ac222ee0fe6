//! Which view the refiner attends to beside each rendered frame, and how to pick it.
//!
//! Difix's reference-view mode lets the UNet's self-attention span a second image: a real photograph of the
//! scene, so that the refiner can copy detail rather than invent it. For a rendered frame the natural
//! reference is the input view of the same camera nearest in time (`dggt_scene::nearest_in_time`) — what the
//! refiner's training pairs use (`dggt refine-pairs`) and what `dggt reconstruct`, `dggt eval` and
//! `dggt bench` take with `--refine-reference nearest-input`.

use crate::error::UnknownName;

/// The view each refined frame attends to.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceView {
    /// None: the single-view mode.
    #[default]
    None,
    /// The input view of the frame's camera nearest in time (the earlier of two as near).
    NearestInput,
}

impl ReferenceView {
    /// The name used on command lines and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::NearestInput => "nearest-input",
        }
    }
}

impl std::str::FromStr for ReferenceView {
    type Err = UnknownName;

    fn from_str(text: &str) -> Result<Self, UnknownName> {
        [Self::None, Self::NearestInput].into_iter().find(|view| view.name() == text).ok_or_else(|| UnknownName {
            what: "reference view",
            text: text.to_string(),
            expected: "none or nearest-input",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back() {
        for view in [ReferenceView::None, ReferenceView::NearestInput] {
            assert_eq!(view.name().parse::<ReferenceView>(), Ok(view));
        }
        let error = "nearest".parse::<ReferenceView>().unwrap_err().to_string();
        assert!(error.contains("\"nearest\"") && error.contains("nearest-input"), "{error}");
    }
}
