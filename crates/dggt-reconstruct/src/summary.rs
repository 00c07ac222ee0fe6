//! What a reconstruction reports: frames, Gaussians kept per stage, time per stage, peak memory, warnings and
//! every file written; printed on stdout and saved as `summary.json`.

use std::fmt;
use std::path::PathBuf;

use serde::Serialize;

use crate::align::PoseError;
use dggt_infer::CheckpointInfo;

/// Seconds spent in one stage.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

/// Gaussians at each stage of the export.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct GaussianCounts {
    /// One per input pixel.
    pub per_pixel: usize,
    /// Static opacity at least 1/255 (`gaussians/static.ply`).
    pub static_kept: usize,
    /// Sky Gaussians seen by at least one input view (`gaussians/sky.ply`).
    pub sky_kept: usize,
    /// Per requested time: dynamic opacity at least 1/255 (`gaussians/dynamic_tNNNN.ply`).
    pub dynamic_kept: Vec<usize>,
}

/// One rendered frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderRecord {
    pub file: String,
    pub camera: usize,
    /// Seconds since the first chosen frame.
    pub time_s: f64,
    /// Whether `time_s` is an input frame's time.
    pub at_input: bool,
    /// `images/NAME.png`: the input view of this camera nearest in time (the earlier of two as near), the
    /// refiner's reference view (`--refine-reference nearest-input`).
    pub nearest_input: String,
    /// Candidates before culling, and what culling dropped and kept.
    pub candidates: usize,
    pub transparent: usize,
    pub off_screen: usize,
    pub static_kept: usize,
    pub dynamic_kept: usize,
}

/// One moving object found among the dynamic pixels (`dggt_instances`). Positions are in the reconstruction's
/// world (the first input camera's frame, OpenCV axes, the network's predicted units); times are scene times.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InstanceRecord {
    pub id: u32,
    /// One per input time it was seen at, in time order.
    pub appearances: Vec<InstanceAppearance>,
    /// Registration residual (root mean square, world units) of each step between consecutive appearances.
    pub residuals: Vec<f64>,
}

/// An object at one input time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InstanceAppearance {
    pub scene_time: f64,
    /// The input's log frame (its index in the source) at that time.
    pub frame: usize,
    /// The input views it was seen in (positions in the views' order).
    pub views: Vec<usize>,
    /// Its dynamic pixels over those views.
    pub pixels: usize,
    /// World-axis-aligned box of its points.
    pub box_min: [f64; 3],
    pub box_max: [f64; 3],
    pub centre: [f64; 3],
    /// The rigid motion from its first appearance to this one: rotation `w x y z`, then translation.
    pub rotation_wxyz: [f64; 4],
    pub translation: [f64; 3],
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub input: PathBuf,
    pub input_kind: String,
    pub frames: usize,
    pub cameras: Vec<String>,
    pub views: usize,
    /// `[width, height]` of the input images.
    pub input_size: [u32; 2],
    /// `[width, height]` the network ran at.
    pub network_size: [u32; 2],
    pub checkpoint: CheckpointInfo,
    pub device: String,
    pub gaussians: GaussianCounts,
    /// Requested times, seconds since the first chosen frame.
    pub times_s: Vec<f64>,
    pub renders: Vec<RenderRecord>,
    /// PSNR of each input view re-rendered from the reconstruction against the preprocessed input (dB).
    pub input_psnr_db: Vec<f64>,
    /// Predicted poses against the source's (scene exports only), after similarity alignment.
    pub pose_error: Option<PoseError>,
    /// The moving objects found among the dynamic pixels (none without a dynamic head).
    pub instances: Vec<InstanceRecord>,
    pub stages: Vec<StageTime>,
    /// Peak resident memory of the process (`VmHWM`), MiB.
    pub peak_memory_mib: Option<f64>,
    pub warnings: Vec<String>,
    /// Every file written, relative to the output folder.
    pub files: Vec<String>,
}

/// Peak resident set size of this process in MiB, from `/proc/self/status` (Linux).
pub fn peak_memory_mib() -> Option<f64> {
    process_status_mib("VmHWM:")
}

/// Resident set size of this process now, in MiB (Linux).
pub fn resident_memory_mib() -> Option<f64> {
    process_status_mib("VmRSS:")
}

/// The `/proc/self/status` figure `key` (in kiB there) in MiB.
fn process_status_mib(key: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "input: {} ({}), {} frames x {} cameras = {} views at {}x{}, network at {}x{}",
            self.input.display(),
            self.input_kind,
            self.frames,
            self.cameras.len(),
            self.views,
            self.input_size[0],
            self.input_size[1],
            self.network_size[0],
            self.network_size[1]
        )?;
        let c = &self.checkpoint;
        write!(
            f,
            "checkpoint: {} ({}, {} parameters, architecture {})",
            c.path.display(),
            c.format,
            c.parameters,
            c.architecture
        )?;
        if c.fresh_modules.is_empty() {
            writeln!(f)?;
        } else {
            writeln!(f, "; untrained: {}", c.fresh_modules.join(", "))?;
        }
        let g = &self.gaussians;
        let dynamic_total: usize = g.dynamic_kept.iter().sum();
        writeln!(
            f,
            "gaussians: {} per-pixel -> {} static kept, {} dynamic kept over {} times, {} sky",
            g.per_pixel,
            g.static_kept,
            dynamic_total,
            g.dynamic_kept.len(),
            g.sky_kept
        )?;
        if !self.instances.is_empty() {
            let seen: Vec<String> =
                self.instances.iter().map(|i| format!("{} at {} inputs", i.id, i.appearances.len())).collect();
            writeln!(f, "moving objects: {} ({})", self.instances.len(), seen.join(", "))?;
        }
        if !self.renders.is_empty() {
            let mean = |x: fn(&RenderRecord) -> usize| {
                self.renders.iter().map(x).sum::<usize>() as f64 / self.renders.len() as f64
            };
            writeln!(
                f,
                "renders: {} frames at {} times; per frame on average {:.0} candidates, {:.0} transparent, {:.0} off \
                 screen, {:.0} kept",
                self.renders.len(),
                self.times_s.len(),
                mean(|r| r.candidates),
                mean(|r| r.transparent),
                mean(|r| r.off_screen),
                mean(|r| r.static_kept + r.dynamic_kept)
            )?;
        }
        if !self.input_psnr_db.is_empty() {
            let mean = self.input_psnr_db.iter().sum::<f64>() / self.input_psnr_db.len() as f64;
            writeln!(f, "inputs re-rendered: mean PSNR {mean:.2} dB")?;
        }
        if let Some(e) = &self.pose_error {
            writeln!(
                f,
                "poses vs the source (similarity-aligned): centre RMSE {:.3} ({:.1} % of the trajectory spread), \
                 rotation mean {:.2} deg, max {:.2} deg",
                e.centre_rmse,
                100.0 * e.centre_rmse_relative,
                e.rotation_mean_deg,
                e.rotation_max_deg
            )?;
        }
        let stages: Vec<String> = self.stages.iter().map(|s| format!("{} {:.2} s", s.stage, s.seconds)).collect();
        writeln!(f, "time: {}", stages.join(", "))?;
        if let Some(mib) = self.peak_memory_mib {
            writeln!(f, "peak memory: {mib:.0} MiB")?;
        }
        for warning in &self.warnings {
            writeln!(f, "warning: {warning}")?;
        }
        write!(f, "{} files written", self.files.len())
    }
}
