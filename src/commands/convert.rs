//! `dggt convert`: raw driving datasets (Waymo, Argoverse 2, nuScenes) into the scene-export layout, one numbered scene
//! folder per segment.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Duration;

use anyhow::{Context, Result};
use dggt_convert::batch::{self, ExistingScenes, FailurePolicy, Outcome, Progress, ProgressUnit, SegmentJob};
use dggt_convert::masks::DynamicMaskStyle as MaskStyle;
use dggt_convert::nuscenes::{FrameRate, NuScenesVersion};
use dggt_convert::sky;
use dggt_convert::undistort::Lens;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

/// The raw datasets `dggt convert` reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Dataset {
    /// Waymo Open Dataset v1: one `Frame` TFRecord per segment.
    Waymo,
    /// Argoverse 2 sensor logs: one log folder, or a split folder of logs.
    Argoverse2,
    /// nuScenes: the data root; every row of the version's scene table is a segment (key frames, 2 Hz).
    Nuscenes,
}

/// nuScenes frames: the annotated key frames, or drivestudio's `--interpolate_N` frames between them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum NuscenesRate {
    /// Key frames only (drivestudio's default).
    #[value(name = "2hz")]
    KeyFrames,
    #[value(name = "4hz")]
    Hz4,
    #[value(name = "6hz")]
    Hz6,
    #[value(name = "8hz")]
    Hz8,
    /// Four frames between key frames (drivestudio's documented `--interpolate_N 4`).
    #[value(name = "10hz")]
    Hz10,
}

impl NuscenesRate {
    fn frame_rate(self) -> FrameRate {
        match self {
            Self::KeyFrames => FrameRate::KeyFrames,
            Self::Hz4 => FrameRate::Interpolated { between: 1 },
            Self::Hz6 => FrameRate::Interpolated { between: 2 },
            Self::Hz8 => FrameRate::Interpolated { between: 3 },
            Self::Hz10 => FrameRate::Interpolated { between: 4 },
        }
    }
}

/// Sky masks to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SkyMasks {
    /// None (the trainer then skips the sky-opacity term).
    None,
    /// Approximate masks from the lidar: rows above the highest projected return of each column.
    Lidar,
}

/// Depth-flow maps to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthFlows {
    /// None (depth then comes from the lidar sweeps, which carry no scene flow).
    None,
    /// `depth_flows_4/`: lidar depth and scene flow from the tracked boxes, for scoring motion.
    Boxes,
}

/// Dynamic masks to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DynamicMasks {
    /// The objects whose tracks move (faster than `--moving-speed`), each as its projected 3D box outline, placed
    /// at the camera's own time; parked cars are static.
    Moving,
    /// The release's data exactly: drivestudio's rectangles (every box of a masked class on nuScenes and
    /// Argoverse 2, parked cars included; boxes the lidar saw faster than 1 m/s on Waymo).
    Drivestudio,
}

/// Argoverse 2's lens distortion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ArgoverseLens {
    /// Images resampled to the pinhole camera the export's intrinsics describe, so that masks and lidar agree
    /// with the pixels to the image's edges (the lens moves an edge pixel by about 100 px).
    Undistorted,
    /// The release's data: the recorded images, the distortion dropped from the intrinsics.
    AsRecorded,
}

impl Dataset {
    fn converter(self, version: NuScenesVersion, rate: NuscenesRate, lens: ArgoverseLens) -> batch::Dataset {
        match self {
            Self::Waymo => batch::Dataset::Waymo,
            Self::Argoverse2 => batch::Dataset::Argoverse2(match lens {
                ArgoverseLens::Undistorted => Lens::Undistorted,
                ArgoverseLens::AsRecorded => Lens::AsRecorded,
            }),
            Self::Nuscenes => batch::Dataset::NuScenes(version, rate.frame_rate()),
        }
    }
}

/// Convert raw driving logs into the scene-export layout (drivestudio's per-dataset variant).
#[derive(Debug, clap::Args)]
pub struct Args {
    dataset: Dataset,
    /// A segment (Waymo `.tfrecord` file, Argoverse 2 log folder), or a folder of them (sorted by name; segment i
    /// becomes scene {i:03}); for nuScenes the data root (scene i = row i of the scene table).
    #[arg(long)]
    input: PathBuf,
    /// The folder that receives the scene folders.
    #[arg(long)]
    out: PathBuf,
    /// Only these scene numbers (positions in the sorted input), e.g. `0,3,7`.
    #[arg(long, value_delimiter = ',')]
    scenes: Option<Vec<usize>>,
    /// Export camera ids to write, all by default (Waymo: 0 FRONT, 1 FRONT_LEFT, 2 FRONT_RIGHT, 3 SIDE_LEFT,
    /// 4 SIDE_RIGHT; Argoverse 2: 0 ring_front_center .. 6 ring_rear_right; nuScenes: 0 CAM_FRONT, 1 CAM_FRONT_LEFT,
    /// 2 CAM_FRONT_RIGHT, 3 CAM_BACK_LEFT, 4 CAM_BACK_RIGHT, 5 CAM_BACK).
    #[arg(long, value_delimiter = ',')]
    cameras: Option<Vec<usize>>,
    /// Segments converted at once (default: the machine's cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Convert every segment that can be converted and list the others, instead of stopping at the first failure.
    #[arg(long)]
    keep_going: bool,
    /// nuScenes release: the folder of devkit tables under the data root (v1.0-mini, v1.0-trainval, v1.0-test,
    /// or any other folder holding the tables).
    #[arg(long, default_value = "v1.0-mini")]
    version: NuScenesVersion,
    /// nuScenes frame rate: the 2 Hz key frames, or frames between them (nearest camera and lidar readings,
    /// interpolated boxes).
    #[arg(long, value_enum, default_value = "2hz")]
    nuscenes_rate: NuscenesRate,
    /// Sky masks (`lidar`: approximate, from the projected lidar returns; recorded in `sky_masks/SOURCE.txt`).
    #[arg(long, value_enum, default_value = "none")]
    sky_masks: SkyMasks,
    /// Depth-flow maps (`boxes`: `depth_flows_4/` with the lidar's depth and the scene flow of points inside
    /// tracked boxes, metres per second in the log's world; about 16 bytes per 16 pixels of every image).
    #[arg(long, value_enum, default_value = "none")]
    depth_flows: DepthFlows,
    /// Dynamic masks (recorded in `dynamic_masks/SOURCE.txt`).
    #[arg(long, value_enum, default_value = "moving")]
    dynamic_masks: DynamicMasks,
    /// With `--dynamic-masks moving`: the horizontal speed (m/s) above which an object moves, from its track's
    /// displacement over a second (Waymo: its annotated speed).
    #[arg(long, default_value_t = dggt_convert::tracks::DEFAULT_MOVING_SPEED_M_S)]
    moving_speed: f64,
    /// Argoverse 2: the images undistorted to the pinhole camera (recorded in the done marker), or as recorded.
    #[arg(long, value_enum, default_value = "undistorted")]
    argoverse_lens: ArgoverseLens,
    /// Convert the chosen scenes again even when their folders exist, replacing each once its new version is
    /// complete. Without it, a scene finished from the same source with the same options is skipped and any
    /// other folder in its place is refused.
    #[arg(long)]
    overwrite: bool,
}

pub fn run(args: Args) -> Result<()> {
    let Args {
        dataset,
        input,
        out,
        scenes,
        cameras,
        workers,
        keep_going,
        version,
        nuscenes_rate,
        sky_masks,
        depth_flows,
        dynamic_masks,
        moving_speed,
        argoverse_lens,
        overwrite,
    } = args;
    if !(moving_speed.is_finite() && moving_speed >= 0.0) {
        anyhow::bail!("--moving-speed: expected a finite speed of 0 m/s or more, found {moving_speed}");
    }
    let dataset = dataset.converter(version, nuscenes_rate, argoverse_lens);
    let names = dataset.variant().camera_names();
    let cameras = cameras.unwrap_or_else(|| (0..names.len()).collect());
    if let Some(unknown) = cameras.iter().find(|&&c| c >= names.len()) {
        anyhow::bail!("unknown camera {unknown}: {} export ids are 0..={}", dataset.variant(), names.len() - 1);
    }
    let jobs = batch::jobs(&dataset, &input, &out, scenes.as_deref()).context("listing the segments")?;
    let workers = workers.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let policy = if keep_going { FailurePolicy::KeepGoing } else { FailurePolicy::Stop };
    let bars = Bars::new(jobs.len());
    let started = std::time::Instant::now();
    let sky_masks = match sky_masks {
        SkyMasks::None => sky::SkyMasks::None,
        SkyMasks::Lidar => sky::SkyMasks::Lidar,
    };
    let depth_flows = match depth_flows {
        DepthFlows::None => dggt_convert::depth_flows::DepthFlows::None,
        DepthFlows::Boxes => dggt_convert::depth_flows::DepthFlows::FromBoxes,
    };
    let dynamic_masks = match dynamic_masks {
        DynamicMasks::Moving => MaskStyle::MovingOutlines { min_speed_m_s: moving_speed },
        DynamicMasks::Drivestudio => MaskStyle::Drivestudio,
    };
    let options = batch::ConvertOptions { cameras, sky_masks, depth_flows, dynamic_masks };
    let existing = if overwrite { ExistingScenes::Replace } else { ExistingScenes::Keep };
    let outcomes = batch::convert_segments(&dataset, &jobs, &options, workers, policy, existing, &bars)?;
    bars.overall.finish_and_clear();
    report(&jobs, &outcomes, started.elapsed())
}

/// Prints what became of each segment; fails when any segment failed or was refused.
fn report(jobs: &[SegmentJob], outcomes: &[Outcome], elapsed: Duration) -> Result<()> {
    let (mut failures, mut refusals) = (Vec::new(), Vec::new());
    let (mut converted, mut skipped, mut frames) = (0, 0, 0);
    for (job, outcome) in jobs.iter().zip(outcomes) {
        match outcome {
            Outcome::Converted(summary) => {
                converted += 1;
                frames += summary.frames;
            }
            Outcome::AlreadyDone(_) => skipped += 1,
            Outcome::Refused(refusal) => refusals.push(format!(
                "{}: {refusal}; convert with the earlier options, into another --out, or pass --overwrite to convert \
                 it again",
                job.scene.display()
            )),
            Outcome::Failed(error) => failures.push(format!("{}: {error}", job.describe())),
            Outcome::NotStarted => {}
        }
    }
    println!(
        "converted {converted} segments ({frames} frames) in {:.1} s; {skipped} already done; {} refused; {} failed",
        elapsed.as_secs_f64(),
        refusals.len(),
        failures.len()
    );
    for refusal in &refusals {
        eprintln!("refused: {refusal}");
    }
    for failure in &failures {
        eprintln!("failed: {failure}");
    }
    let unfinished = refusals.len() + failures.len();
    anyhow::ensure!(unfinished == 0, "{unfinished} of {} segments failed or were refused", jobs.len());
    Ok(())
}

/// An overall bar (segments) and one bar per running segment (bytes read).
struct Bars {
    multi: MultiProgress,
    overall: ProgressBar,
    segments: Mutex<HashMap<usize, ProgressBar>>,
}

impl Bars {
    fn new(segments: usize) -> Self {
        let multi = MultiProgress::new();
        let overall = multi.add(ProgressBar::new(segments as u64));
        overall.set_style(
            ProgressStyle::with_template("segments {bar:30} {pos}/{len} [{elapsed_precise}]")
                .expect("a valid template"),
        );
        Self { multi, overall, segments: Mutex::new(HashMap::new()) }
    }

    fn bar(&self, job: &SegmentJob) -> Option<ProgressBar> {
        self.segments.lock().ok()?.get(&job.index).cloned()
    }
}

impl Progress for Bars {
    fn started(&self, job: &SegmentJob, total: u64, unit: ProgressUnit) {
        let bar = self.multi.add(ProgressBar::new(total));
        let template = match unit {
            ProgressUnit::Bytes => "{prefix:>4} {bar:30} {bytes}/{total_bytes} {msg}",
            ProgressUnit::Sweeps => "{prefix:>4} {bar:30} {pos}/{len} sweeps {msg}",
            ProgressUnit::Frames => "{prefix:>4} {bar:30} {pos}/{len} frames {msg}",
        };
        bar.set_style(ProgressStyle::with_template(template).expect("a valid template"));
        bar.set_prefix(format!("{:03}", job.index));
        bar.set_message(job.name.clone());
        if let Ok(mut segments) = self.segments.lock() {
            segments.insert(job.index, bar);
        }
    }

    fn advanced(&self, job: &SegmentJob, done: u64) {
        if let Some(bar) = self.bar(job) {
            bar.set_position(done);
        }
    }

    fn finished(&self, job: &SegmentJob, _outcome: &Outcome) {
        if let Some(bar) = self.segments.lock().ok().and_then(|mut segments| segments.remove(&job.index)) {
            bar.finish_and_clear();
        }
        self.overall.inc(1);
    }
}
