//! A window of frames asked of a scene (`--frames`, `data.frames`, an evaluation protocol's window) checked
//! against the frames the scene has, so that a window reaching past them is said in those words, with the
//! scene's frame count, rather than as the first file it lacks.

use std::fmt;
use std::ops::Range;

/// A window with frames the scene lacks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramesOutside {
    pub window: Range<usize>,
    /// The scene's frame indices: how many, the first and the last (none when it has no frames).
    pub scene: Option<(usize, usize, usize)>,
    /// Frames of the window the scene lacks: how many, and the first of them.
    pub missing: usize,
    pub first_missing: usize,
}

/// What of `window` the scene with frame indices `frames` (ascending) lacks, if anything.
pub fn frames_outside(window: &Range<usize>, frames: &[usize]) -> Option<FramesOutside> {
    let missing: Vec<usize> = window.clone().filter(|f| frames.binary_search(f).is_err()).collect();
    let first_missing = *missing.first()?;
    let scene = match (frames.first(), frames.last()) {
        (Some(&first), Some(&last)) => Some((frames.len(), first, last)),
        _ => None,
    };
    Some(FramesOutside { window: window.clone(), scene, missing: missing.len(), first_missing })
}

impl fmt::Display for FramesOutside {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Range { start, end } = self.window;
        let have = match self.scene {
            Some((count, first, last)) => format!("the scene's {count} frames ({first}..={last})"),
            None => "the scene, which has no frames".into(),
        };
        write!(
            f,
            "too few frames: the window {start}..{end} (frames {start}..={}) reaches past {have}: {} of its frames \
             are missing, the first {}",
            end.saturating_sub(1),
            self.missing,
            self.first_missing
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_past_the_scene_names_its_frames() {
        let frames: Vec<usize> = (0..20).collect();
        assert_eq!(frames_outside(&(3..20), &frames), None);
        let outside = frames_outside(&(0..1000), &frames).unwrap();
        assert_eq!((outside.missing, outside.first_missing), (980, 20));
        let text = outside.to_string();
        assert!(text.contains("0..1000") && text.contains("20 frames (0..=19)"), "{text}");
        assert!(frames_outside(&(0..2), &[]).unwrap().to_string().contains("no frames"));
    }
}
