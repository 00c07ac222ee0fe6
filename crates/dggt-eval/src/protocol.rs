//! Evaluation protocols: which frames of a window are the network's inputs, which are rendered and scored, and
//! under which split each scored view is reported.
//!
//! - [`ProtocolKind::Paper`] (the DGGT paper): a 20-frame window, inputs at its frames 0, 5, 10 and 15, every
//!   frame of the window predicted for cameras 0-2; the input frames are reported as *reconstruction*, the
//!   other 16 as *novel view* synthesis (frames 16-19 lie beyond the last input, so they are extrapolated).
//! - [`ProtocolKind::Reconstruction`] (the release's reconstruction mode): every frame of the window is an
//!   input and is scored (*reconstruction*).
//! - [`ProtocolKind::Interpolation`] (the release's interpolation mode): every `every`-th frame of the window
//!   (offsets 0, I, 2I, ...) is an input; every frame is scored, the inputs as *reconstruction* and the frames
//!   between them as *interpolated*.
//!
//! Frames are the export's frame indices; the window is `start..start + length` (end exclusive). Cameras are
//! export camera ids (0 = FRONT, 1 = FRONT_LEFT, 2 = FRONT_RIGHT in Waymo exports).

use std::fmt;
use std::path::Path;

use serde::Serialize;

use crate::error::EvalError;

/// The paper's input stride.
pub const PAPER_EVERY: usize = 5;
/// The default window length (the paper's).
pub const DEFAULT_WINDOW: usize = 20;
/// The default cameras (the paper's three front cameras).
pub const DEFAULT_CAMERAS: [usize; 3] = [0, 1, 2];

/// Which protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ProtocolKind {
    Paper,
    Reconstruction,
    Interpolation,
}

impl fmt::Display for ProtocolKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Paper => "paper",
            Self::Reconstruction => "reconstruction",
            Self::Interpolation => "interpolation",
        })
    }
}

/// How a scored view is reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// An input view re-rendered.
    Reconstruction,
    /// A frame that is no input, paper protocol.
    NovelView,
    /// A frame between inputs, interpolation protocol.
    Interpolated,
}

impl Split {
    /// The heading of the split in reports.
    pub fn title(self) -> &'static str {
        match self {
            Self::Reconstruction => "reconstruction (input frames)",
            Self::NovelView => "novel view synthesis (frames that are no input)",
            Self::Interpolated => "interpolated (frames between inputs)",
        }
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Reconstruction => "reconstruction",
            Self::NovelView => "novel_view",
            Self::Interpolated => "interpolated",
        })
    }
}

/// One protocol with its window and cameras.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Protocol {
    pub kind: ProtocolKind,
    /// First frame index of the window.
    pub start: usize,
    /// Frames in the window.
    pub length: usize,
    /// Input stride (1 for reconstruction, 5 for the paper).
    pub every: usize,
    /// Export camera ids, in the order the views are batched.
    pub cameras: Vec<usize>,
}

impl Protocol {
    /// The paper's protocol on frames `0..20` of cameras 0-2.
    pub fn paper() -> Self {
        Self {
            kind: ProtocolKind::Paper,
            start: 0,
            length: DEFAULT_WINDOW,
            every: PAPER_EVERY,
            cameras: DEFAULT_CAMERAS.to_vec(),
        }
    }

    /// The release's reconstruction mode: frames `start..start + length` are inputs and are scored.
    pub fn reconstruction(start: usize, length: usize, cameras: Vec<usize>) -> Self {
        Self { kind: ProtocolKind::Reconstruction, start, length, every: 1, cameras }
    }

    /// The release's interpolation mode: every `every`-th frame of the window is an input.
    pub fn interpolation(start: usize, length: usize, every: usize, cameras: Vec<usize>) -> Self {
        Self { kind: ProtocolKind::Interpolation, start, length, every, cameras }
    }

    /// Checks the settings themselves (not yet against a scene).
    pub fn validate(&self) -> Result<(), EvalError> {
        if self.length == 0 {
            return Err(EvalError::invalid("--frames", "the window is empty"));
        }
        if self.every == 0 {
            return Err(EvalError::invalid("--every", "must be at least 1"));
        }
        if self.kind == ProtocolKind::Paper && self.every != PAPER_EVERY {
            return Err(EvalError::invalid(
                "--every",
                format!(
                    "the paper protocol takes every {PAPER_EVERY}th frame as input; use --protocol interpolation \
                     for another stride"
                ),
            ));
        }
        if self.kind == ProtocolKind::Reconstruction && self.every != 1 {
            return Err(EvalError::invalid("--every", "the reconstruction protocol takes every frame as input"));
        }
        if self.cameras.is_empty() {
            return Err(EvalError::invalid("--cameras", "no camera chosen"));
        }
        let mut sorted = self.cameras.clone();
        sorted.sort_unstable();
        sorted.dedup();
        if sorted.len() != self.cameras.len() {
            return Err(EvalError::invalid("--cameras", format!("{:?} names a camera twice", self.cameras)));
        }
        Ok(())
    }

    /// The window's frame indices.
    pub fn window(&self) -> std::ops::Range<usize> {
        self.start..self.start + self.length
    }

    /// The input frame indices, ascending.
    pub fn input_frames(&self) -> Vec<usize> {
        self.window().step_by(self.every).collect()
    }

    /// Every scored frame with its split, ascending.
    pub fn targets(&self) -> Vec<(usize, Split)> {
        let inputs = self.input_frames();
        let other = match self.kind {
            ProtocolKind::Paper => Split::NovelView,
            ProtocolKind::Reconstruction | ProtocolKind::Interpolation => Split::Interpolated,
        };
        self.window().map(|f| (f, if inputs.contains(&f) { Split::Reconstruction } else { other })).collect()
    }

    /// The splits this protocol reports, in report order.
    pub fn splits(&self) -> Vec<Split> {
        let mut splits: Vec<Split> = self.targets().into_iter().map(|(_, s)| s).collect();
        splits.sort_unstable();
        splits.dedup();
        splits
    }

    /// Checks that a scene with frame indices `frames` (ascending) has the whole window.
    pub fn check_frames(&self, scene: &Path, frames: &[usize]) -> Result<(), EvalError> {
        let missing: Vec<usize> = self.window().filter(|f| frames.binary_search(f).is_err()).collect();
        if missing.is_empty() {
            return Ok(());
        }
        let have = match (frames.first(), frames.last()) {
            (Some(first), Some(last)) => format!("{} frames ({first}..={last})", frames.len()),
            _ => "no frames".into(),
        };
        Err(EvalError::scene(
            scene,
            format!(
                "too few frames: the {} protocol's window {:?} needs frames {}..={}, the scene has {have} (missing \
                 {} of them, first {}); choose another window with --frames",
                self.kind,
                self.window(),
                self.start,
                self.start + self.length - 1,
                missing.len(),
                missing[0]
            ),
        ))
    }
}
