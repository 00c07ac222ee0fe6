//! What to synthesise: seed, sequence length, number of cameras and image size.
//!
//! The configuration is the only input of the generator: the same configuration always yields the same scene and
//! byte-identical files. [`SynthConfig::validate`] rejects values the generator does not support.

use serde::{Deserialize, Serialize};

use crate::error::{Result, SynthError};

/// Seconds between consecutive frames (10 Hz, as Waymo): frame `t` is captured at `t * 0.1` s.
pub const FRAME_INTERVAL_S: f64 = 0.1;
/// Cameras available on the synthetic rig: 0 FRONT, 1 FRONT_LEFT, 2 FRONT_RIGHT.
pub const MAX_CAMERAS: usize = 3;
/// Longest supported sequence (100 s of driving).
pub const MAX_FRAMES: usize = 1000;
/// Smallest image side: the quarter-resolution depth maps need at least one sample per side.
pub const MIN_IMAGE_SIDE: u32 = 4;
/// Largest image side.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Arguments of the generator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SynthConfig {
    /// Randomises placements, colours and speeds.
    pub seed: u64,
    /// Number of frames, at [`FRAME_INTERVAL_S`] apart.
    pub frames: usize,
    /// Number of cameras, `1..=3`: FRONT, then FRONT_LEFT, then FRONT_RIGHT.
    pub cameras: usize,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Default for SynthConfig {
    /// The size of the committed fixture: 20 frames from 3 cameras at 160x112.
    fn default() -> Self {
        Self { seed: 0, frames: 20, cameras: 3, width: 160, height: 112 }
    }
}

impl SynthConfig {
    /// Checks every field against the supported ranges.
    pub fn validate(&self) -> Result<()> {
        let invalid = |message: String| Err(SynthError::InvalidConfig(message));
        if self.frames == 0 || self.frames > MAX_FRAMES {
            return invalid(format!("frames must be in 1..={MAX_FRAMES}, got {}", self.frames));
        }
        if self.cameras == 0 || self.cameras > MAX_CAMERAS {
            return invalid(format!("cameras must be in 1..={MAX_CAMERAS}, got {}", self.cameras));
        }
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if !(MIN_IMAGE_SIDE..=MAX_IMAGE_SIDE).contains(&side) {
                return invalid(format!("{name} must be in {MIN_IMAGE_SIDE}..={MAX_IMAGE_SIDE} pixels, got {side}"));
            }
        }
        Ok(())
    }

    /// Capture time of `frame` in seconds.
    pub fn frame_time(frame: usize) -> f64 {
        frame as f64 / 10.0
    }

    /// Time between the first and the last frame, in seconds.
    pub fn duration(&self) -> f64 {
        Self::frame_time(self.frames.saturating_sub(1))
    }

    /// The `dggt synth` command line that reproduces this configuration (`DIR` stands for the output folder).
    pub fn command_line(&self) -> String {
        format!(
            "dggt synth --out DIR --seed {} --frames {} --cameras {} --width {} --height {}",
            self.seed, self.frames, self.cameras, self.width, self.height
        )
    }
}
