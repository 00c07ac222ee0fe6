//! Evaluation protocols: which frames of a window are the network's inputs, which are rendered and scored, and
//! under which split each scored view is reported.
//!
//! - [`ProtocolKind::Paper`] (the DGGT paper): a 20-frame window, inputs at its frames 0, 5, 10 and 15, every
//!   frame of the window predicted for cameras 0-2; the input frames are reported as *reconstruction*, the
//!   other 16 as *novel view* synthesis (frames 16-19 lie beyond the last input, so they are extrapolated).
//! - [`ProtocolKind::Reconstruction`] (the release's reconstruction mode): every frame of the window is an
//!   input and is scored (*reconstruction*).
//! - [`ProtocolKind::Interpolation`] (the release's interpolation mode): every `every`-th frame of the window
//!   (offsets 0, I, 2I, ...) is an input; every frame is scored, the inputs as *reconstruction*, the frames
//!   between them as *interpolated* and those after the last input (when the stride does not end on the
//!   window's last frame) as *extrapolated*. The stride leaves at least two inputs in the window.
//!
//! `scored` narrows the frames scored besides the inputs to a list (the frames a training run held out, say, so
//! that every scored frame between the inputs is one the model never trained on); the inputs are always scored.
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
pub enum TargetKind {
    /// An input view re-rendered.
    Reconstruction,
    /// A frame that is no input, paper protocol.
    NovelView,
    /// A frame between inputs, interpolation protocol.
    Interpolated,
    /// A frame after the last input, interpolation protocol.
    Extrapolated,
}

impl TargetKind {
    /// The heading of the split in reports.
    pub fn title(self) -> &'static str {
        match self {
            Self::Reconstruction => "reconstruction (input frames)",
            Self::NovelView => "novel view synthesis (frames that are no input)",
            Self::Interpolated => "interpolated (frames between inputs)",
            Self::Extrapolated => "extrapolated (frames beyond the last input)",
        }
    }
}

impl fmt::Display for TargetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Reconstruction => "reconstruction",
            Self::NovelView => "novel_view",
            Self::Interpolated => "interpolated",
            Self::Extrapolated => "extrapolated",
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
    /// The frames scored besides the inputs; every other frame of the window when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scored: Option<Vec<usize>>,
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
            scored: None,
        }
    }

    /// The release's reconstruction mode: frames `start..start + length` are inputs and are scored.
    pub fn reconstruction(start: usize, length: usize, cameras: Vec<usize>) -> Self {
        Self { kind: ProtocolKind::Reconstruction, start, length, every: 1, cameras, scored: None }
    }

    /// The release's interpolation mode: every `every`-th frame of the window is an input.
    pub fn interpolation(start: usize, length: usize, every: usize, cameras: Vec<usize>) -> Self {
        Self { kind: ProtocolKind::Interpolation, start, length, every, cameras, scored: None }
    }

    /// Checks the settings themselves (not yet against a scene).
    pub fn validate(&self) -> Result<(), EvalError> {
        if self.length == 0 {
            return Err(EvalError::option("--frames", "the window is empty"));
        }
        if self.every == 0 {
            return Err(EvalError::option("--every", "must be at least 1"));
        }
        if self.kind == ProtocolKind::Paper && self.every != PAPER_EVERY {
            return Err(EvalError::option(
                "--every",
                format!(
                    "the paper protocol takes every {PAPER_EVERY}th frame as input; use --protocol interpolation \
                     for another stride"
                ),
            ));
        }
        if self.kind == ProtocolKind::Reconstruction && self.every != 1 {
            return Err(EvalError::option("--every", "the reconstruction protocol takes every frame as input"));
        }
        if self.kind == ProtocolKind::Interpolation {
            self.check_two_inputs()?;
        }
        if self.cameras.is_empty() {
            return Err(EvalError::option("--cameras", "no camera chosen"));
        }
        let inputs = self.input_frames();
        let outside = |f: &&usize| !self.window().contains(*f) || inputs.contains(*f);
        if let Some(frame) = self.scored.iter().flatten().find(outside) {
            return Err(EvalError::option(
                "--score-frames",
                format!("frame {frame} is not a frame of the window {:?} between or after its inputs", self.window()),
            ));
        }
        let mut sorted = self.cameras.clone();
        sorted.sort_unstable();
        sorted.dedup();
        if sorted.len() != self.cameras.len() {
            return Err(EvalError::option("--cameras", format!("{:?} names a camera twice", self.cameras)));
        }
        Ok(())
    }

    /// Interpolation needs two inputs or more: a window of two frames or more, and a stride shorter than it.
    fn check_two_inputs(&self) -> Result<(), EvalError> {
        if self.length < 2 {
            return Err(EvalError::option(
                "--frames",
                "the interpolation protocol needs a window of two frames or more",
            ));
        }
        if self.every < self.length {
            return Ok(());
        }
        Err(EvalError::option(
            "--every",
            format!(
                "{} leaves one input in the window {:?} ({} frames); the interpolation protocol needs two or more: \
                 give 1..={}",
                self.every,
                self.window(),
                self.length,
                self.length - 1
            ),
        ))
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
    pub fn targets(&self) -> Vec<(usize, TargetKind)> {
        let inputs = self.input_frames();
        let last_input = inputs.last().copied().unwrap_or(self.start);
        let split = |frame: usize| match self.kind {
            _ if inputs.contains(&frame) => TargetKind::Reconstruction,
            ProtocolKind::Paper => TargetKind::NovelView,
            ProtocolKind::Reconstruction | ProtocolKind::Interpolation if frame > last_input => {
                TargetKind::Extrapolated
            }
            ProtocolKind::Reconstruction | ProtocolKind::Interpolation => TargetKind::Interpolated,
        };
        let scored = |frame: &usize| inputs.contains(frame) || self.scored.as_ref().is_none_or(|s| s.contains(frame));
        self.window().filter(scored).map(|f| (f, split(f))).collect()
    }

    /// The splits this protocol reports, in report order.
    pub fn splits(&self) -> Vec<TargetKind> {
        let mut splits: Vec<TargetKind> = self.targets().into_iter().map(|(_, s)| s).collect();
        splits.sort_unstable();
        splits.dedup();
        splits
    }

    /// Checks that a scene with frame indices `frames` (ascending) has the whole window.
    pub fn check_frames(&self, scene: &Path, frames: &[usize]) -> Result<(), EvalError> {
        match dggt_data::frames_outside(&self.window(), frames) {
            None => Ok(()),
            Some(outside) => Err(EvalError::scene(
                scene,
                format!("{outside}, for the {} protocol; choose another window with --frames", self.kind),
            )),
        }
    }
}
