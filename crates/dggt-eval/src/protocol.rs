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
//! `inputs_per_pass` evaluates a long window in overlapping forward passes of at most that many input frames
//! each (a model trained on windows of three inputs sees three at a time): pass `k` takes the inputs
//! `k (n - 1) ..= k (n - 1) + n - 1` and scores the frames from its first input up to (not including) the next
//! pass's first input, the last pass up to the window's end; so every scored frame is scored once, by the pass
//! whose inputs bracket it, and the report's splits are those of the whole window.
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

/// One forward pass of a protocol: its own protocol (its inputs and window) and the frames whose scores it
/// reports (the frames it shares with the next pass are the next pass's).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pass {
    pub protocol: Protocol,
    pub scores: std::ops::Range<usize>,
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
    /// At most this many input frames per forward pass (see the module documentation); all in one pass when
    /// absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inputs_per_pass: Option<usize>,
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
            inputs_per_pass: None,
        }
    }

    /// The release's reconstruction mode: frames `start..start + length` are inputs and are scored.
    pub fn reconstruction(start: usize, length: usize, cameras: Vec<usize>) -> Self {
        Self {
            kind: ProtocolKind::Reconstruction,
            start,
            length,
            every: 1,
            cameras,
            scored: None,
            inputs_per_pass: None,
        }
    }

    /// The release's interpolation mode: every `every`-th frame of the window is an input.
    pub fn interpolation(start: usize, length: usize, every: usize, cameras: Vec<usize>) -> Self {
        Self { kind: ProtocolKind::Interpolation, start, length, every, cameras, scored: None, inputs_per_pass: None }
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
        match (self.inputs_per_pass, self.kind) {
            (Some(n), _) if n < 2 => {
                return Err(EvalError::option(
                    "--inputs-per-pass",
                    format!("a pass needs two inputs or more, got {n}"),
                ));
            }
            (Some(_), ProtocolKind::Paper) => {
                return Err(EvalError::option(
                    "--inputs-per-pass",
                    "the paper protocol is one pass of its four inputs",
                ));
            }
            _ => {}
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

    /// The forward passes this protocol runs: itself, or with [`Protocol::inputs_per_pass`] the overlapping
    /// passes of at most that many inputs, each a protocol of its own, with the frames it alone scores.
    pub fn passes(&self) -> Vec<Pass> {
        let inputs = self.input_frames();
        let per_pass = match self.inputs_per_pass {
            Some(n) if n < inputs.len() => n,
            _ => return vec![Pass { protocol: self.clone(), scores: self.window() }],
        };
        let last = inputs.len() - 1;
        (0..last)
            .step_by(per_pass - 1)
            .map(|first| {
                let final_input = (first + per_pass - 1).min(last);
                let is_last = final_input == last;
                let start = inputs[first];
                let end = if is_last { self.start + self.length } else { inputs[final_input] + 1 };
                let scores = start..if is_last { end } else { inputs[final_input] };
                let window = start..end;
                let scored = self.scored.as_ref().map(|frames| {
                    frames.iter().copied().filter(|f| window.contains(f) && !inputs.contains(f)).collect()
                });
                let protocol = Protocol { start, length: end - start, scored, inputs_per_pass: None, ..self.clone() };
                Pass { protocol, scores }
            })
            .collect()
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
