//! The knobs that trade run time for accuracy, and the sweep over them: a baseline configuration, the exact
//! reference (the baseline with every culling shortcut off), one row per value of each knob with the others at
//! the baseline, and optionally the full grid.
//!
//! Units: widths in pixels (a multiple of the network's 14-pixel patch), opacities in `[0, 1]`.

use std::fmt;

use burn::tensor::FloatDType;

use crate::error::BenchError;
use dggt_infer::SkyChoice;
use dggt_scene::DynamicMotion;

/// Parses how dynamic Gaussians move between inputs: `held`, `velocity`, `instances` or `learnt`.
pub fn parse_motion(text: &str) -> Result<DynamicMotion, BenchError> {
    DynamicMotion::ALL.into_iter().find(|m| m.name().eq_ignore_ascii_case(text.trim())).ok_or_else(|| {
        BenchError::Setting {
            setting: "motion",
            detail: format!("`{text}`: expected held, velocity, instances or learnt"),
        }
    })
}

/// The float type the network (aggregator and heads) computes in. Assembly, the sky model and the rasteriser
/// always compute in f32 (the rasteriser works on flat `f32` buffers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Precision {
    F32,
    F16,
    Bf16,
}

impl Precision {
    pub const ALL: [Precision; 3] = [Self::F32, Self::F16, Self::Bf16];

    pub fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
            Self::Bf16 => "bf16",
        }
    }

    pub fn dtype(self) -> FloatDType {
        match self {
            Self::F32 => FloatDType::F32,
            Self::F16 => FloatDType::F16,
            Self::Bf16 => FloatDType::BF16,
        }
    }

    /// Parses `f32`, `f16` or `bf16`.
    pub fn parse(text: &str) -> Result<Self, BenchError> {
        Self::ALL.into_iter().find(|p| p.name().eq_ignore_ascii_case(text.trim())).ok_or_else(|| BenchError::Setting {
            setting: "precision",
            detail: format!("`{text}`: expected f32, f16 or bf16"),
        })
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which Gaussians reach the rasteriser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Culling {
    /// Every Gaussian, whatever its opacity or footprint (the exact render).
    Off,
    /// Drop Gaussians whose opacity at the target time (after the lifespan fade) is below the threshold, and
    /// those whose footprint misses the image.
    MinOpacity(f32),
}

impl Culling {
    /// The threshold as written in the CSV: `off` or the value.
    pub fn label(self) -> String {
        match self {
            Self::Off => "off".into(),
            Self::MinOpacity(value) => format_opacity(value),
        }
    }
}

/// `1/255` for the rasteriser's own threshold, otherwise the shortest decimal.
pub fn format_opacity(value: f32) -> String {
    if value == dggt_scene::MIN_OPACITY { "1/255".into() } else { format!("{value}") }
}

/// Parses an opacity: a decimal or `N/D` (e.g. `1/255`).
pub fn parse_opacity(text: &str) -> Result<f32, BenchError> {
    let text = text.trim();
    let invalid = || BenchError::Setting {
        setting: "minimum opacity",
        detail: format!("`{text}`: expected a number in [0, 1] such as 0.01 or 1/255"),
    };
    let value = match text.split_once('/') {
        Some((n, d)) => {
            let (n, d): (f64, f64) =
                (n.trim().parse().map_err(|_| invalid())?, d.trim().parse().map_err(|_| invalid())?);
            (n / d) as f32
        }
        None => text.parse::<f32>().map_err(|_| invalid())?,
    };
    if !(0.0..=1.0).contains(&value) {
        return Err(invalid());
    }
    Ok(value)
}

/// The shortcuts that leave out what a scene does not need.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Skips {
    /// Everything runs.
    Nothing,
    /// The motion head only on chunks of frames with a pixel that may be dynamic (renders unchanged).
    StillMotion,
    /// No sky render behind a view the foreground covers (images change by under 1/255 of the sky's colour).
    HiddenSky,
    /// Both.
    All,
}

impl Skips {
    pub const ALL: [Skips; 4] = [Self::Nothing, Self::StillMotion, Self::HiddenSky, Self::All];

    pub fn name(self) -> &'static str {
        match self {
            Self::Nothing => "none",
            Self::StillMotion => "motion",
            Self::HiddenSky => "sky",
            Self::All => "all",
        }
    }

    /// Parses `none`, `motion`, `sky` or `all`.
    pub fn parse(text: &str) -> Result<Self, BenchError> {
        Self::ALL.into_iter().find(|s| s.name().eq_ignore_ascii_case(text.trim())).ok_or_else(|| BenchError::Setting {
            setting: "skips",
            detail: format!("`{text}`: expected none, motion, sky or all"),
        })
    }

    /// Where the motion head runs.
    pub fn motion(self) -> dggt_infer::MotionPath {
        match self {
            Self::StillMotion | Self::All => dggt_infer::MotionPath::WhereDynamic,
            Self::Nothing | Self::HiddenSky => dggt_infer::MotionPath::Always,
        }
    }

    /// Whether a covered sky is rendered.
    pub fn hidden_sky(self) -> dggt_scene::HiddenSky {
        match self {
            Self::HiddenSky | Self::All => dggt_scene::HiddenSky::BELOW_ONE_LEVEL,
            Self::Nothing | Self::StillMotion => dggt_scene::HiddenSky::Render,
        }
    }
}

/// One configuration of the knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knobs {
    /// Network input width in pixels; the height follows the images' aspect (rounded to whole patches).
    pub width: u32,
    /// Input frames given to the network (per camera), evenly spread over the scene's non-target frames.
    pub input_frames: usize,
    pub culling: Culling,
    pub precision: Precision,
    /// Composite the sky model's Gaussians behind the scene, or a black background.
    pub sky: SkyChoice,
    pub skips: Skips,
    /// How the dynamic Gaussians reach the targets' times (with `Instances`, finding the objects is part of
    /// the assembly stage).
    pub motion: DynamicMotion,
}

impl Knobs {
    /// A compact label such as `w112 f8 o1/255 f32 sky skip-none velocity`.
    pub fn label(&self) -> String {
        format!(
            "w{} f{} o{} {} {} skip-{} {}",
            self.width,
            self.input_frames,
            self.culling.label(),
            self.precision,
            match self.sky {
                SkyChoice::Render => "sky",
                SkyChoice::Skip => "nosky",
            },
            self.skips.name(),
            self.motion.name()
        )
    }
}

/// Which knob a row varies from the baseline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Varied {
    /// The exact render: the baseline with culling off. Every row's "vs exact" error is measured against it.
    Reference,
    Baseline,
    Width,
    InputFrames,
    MinOpacity,
    Precision,
    Sky,
    Skips,
    Motion,
    /// A row of the full grid that is not a one-knob variation.
    Grid,
}

impl Varied {
    pub fn name(self) -> &'static str {
        match self {
            Self::Reference => "exact",
            Self::Baseline => "baseline",
            Self::Width => "width",
            Self::InputFrames => "frames",
            Self::MinOpacity => "min_opacity",
            Self::Precision => "precision",
            Self::Sky => "sky",
            Self::Skips => "skips",
            Self::Motion => "motion",
            Self::Grid => "grid",
        }
    }
}

/// One row to measure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Configuration {
    pub varied: Varied,
    pub knobs: Knobs,
}

/// The sweep: the baseline and the values each knob takes.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSpec {
    pub baseline: Knobs,
    pub widths: Vec<u32>,
    pub input_frames: Vec<usize>,
    /// Culling thresholds (off-screen culling is on with every threshold).
    pub min_opacities: Vec<f32>,
    pub precisions: Vec<Precision>,
    pub sky: Vec<SkyChoice>,
    pub skips: Vec<Skips>,
    pub motions: Vec<DynamicMotion>,
    /// Also every combination of the values above.
    pub full_grid: bool,
}

impl Default for SweepSpec {
    /// Width 84 (the tiny model's training width), 8 input frames, the rasteriser's own 1/255 threshold, f32,
    /// with sky, nothing skipped, dynamic Gaussians moved by their velocities; widths 56-168, 4/8/16 frames,
    /// thresholds up to 0.05, f16 and bf16, sky off, each skip, objects moved along their trajectories.
    fn default() -> Self {
        Self {
            baseline: Knobs {
                width: 84,
                input_frames: 8,
                culling: Culling::MinOpacity(dggt_scene::MIN_OPACITY),
                precision: Precision::F32,
                sky: SkyChoice::Render,
                skips: Skips::Nothing,
                motion: DynamicMotion::Velocity,
            },
            widths: vec![56, 84, 112, 168],
            input_frames: vec![4, 8, 16],
            min_opacities: vec![dggt_scene::MIN_OPACITY, 0.01, 0.05],
            precisions: Precision::ALL.to_vec(),
            sky: vec![SkyChoice::Render, SkyChoice::Skip],
            skips: Skips::ALL.to_vec(),
            motions: vec![DynamicMotion::Held, DynamicMotion::Velocity, DynamicMotion::Instances],
            full_grid: false,
        }
    }
}

/// The values to sweep, or the baseline's alone when none are given.
fn or_base<T: Copy>(values: &[T], base: T) -> Vec<T> {
    if values.is_empty() { vec![base] } else { values.to_vec() }
}

impl SweepSpec {
    /// Checks the values that need no scene or network.
    pub fn validate(&self) -> Result<(), BenchError> {
        let invalid = |setting: &'static str, detail: String| Err(BenchError::Setting { setting, detail });
        if let Culling::MinOpacity(value) = self.baseline.culling
            && !(0.0..=1.0).contains(&value)
        {
            return invalid("baseline minimum opacity", format!("{value} is outside [0, 1]"));
        }
        for &width in self.widths.iter().chain([&self.baseline.width]) {
            if width == 0 {
                return invalid("width", "0 pixels".into());
            }
        }
        for &frames in self.input_frames.iter().chain([&self.baseline.input_frames]) {
            if frames < 2 {
                return invalid("input frames", format!("{frames}: at least 2 frames are needed to span a time"));
            }
        }
        if let Some(value) = self.min_opacities.iter().find(|v| !(0.0..=1.0).contains(*v)) {
            return invalid("minimum opacity", format!("{value} is outside [0, 1]"));
        }
        Ok(())
    }

    /// The rows: the exact reference, the baseline, one row per other value of each knob, then (with
    /// `full_grid`) every remaining combination. No configuration appears twice.
    pub fn configurations(&self) -> Vec<Configuration> {
        let base = self.baseline;
        let mut rows = vec![
            Configuration {
                varied: Varied::Reference,
                knobs: Knobs { culling: Culling::Off, skips: Skips::Nothing, ..base },
            },
            Configuration { varied: Varied::Baseline, knobs: base },
        ];
        let mut push = |varied: Varied, knobs: Knobs| {
            if !rows.iter().any(|r| r.knobs == knobs) {
                rows.push(Configuration { varied, knobs });
            }
        };
        for &width in &self.widths {
            push(Varied::Width, Knobs { width, ..base });
        }
        for &input_frames in &self.input_frames {
            push(Varied::InputFrames, Knobs { input_frames, ..base });
        }
        for &value in &self.min_opacities {
            push(Varied::MinOpacity, Knobs { culling: Culling::MinOpacity(value), ..base });
        }
        for &precision in &self.precisions {
            push(Varied::Precision, Knobs { precision, ..base });
        }
        for &sky in &self.sky {
            push(Varied::Sky, Knobs { sky, ..base });
        }
        for &skips in &self.skips {
            push(Varied::Skips, Knobs { skips, ..base });
        }
        for &motion in &self.motions {
            push(Varied::Motion, Knobs { motion, ..base });
        }
        if self.full_grid {
            let widths = if self.widths.is_empty() { vec![base.width] } else { self.widths.clone() };
            let frames = if self.input_frames.is_empty() { vec![base.input_frames] } else { self.input_frames.clone() };
            let cullings: Vec<Culling> = if self.min_opacities.is_empty() {
                vec![base.culling]
            } else {
                self.min_opacities.iter().map(|&v| Culling::MinOpacity(v)).collect()
            };
            let precisions = if self.precisions.is_empty() { vec![base.precision] } else { self.precisions.clone() };
            for &width in &widths {
                for &input_frames in &frames {
                    for &culling in &cullings {
                        for &precision in &precisions {
                            for &sky in &or_base(&self.sky, base.sky) {
                                let knobs = Knobs { width, input_frames, culling, precision, sky, ..base };
                                push(Varied::Grid, knobs);
                            }
                        }
                    }
                }
            }
        }
        rows
    }
}
