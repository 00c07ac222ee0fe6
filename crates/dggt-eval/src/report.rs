//! What an evaluation reports: per-view records, per-scene means split by protocol split, the mean over
//! scenes, stage times; saved as `eval.json` (these structures, stable field names) and `eval.md` (a Markdown
//! table per split).
//!
//! Aggregation: a scene's split value is the mean over its views of that split (views lacking a metric, e.g.
//! no lidar cell for D-RMSE, are left out of that metric's mean and the count says how many took part); the
//! overall value is the mean over the scenes that have one. Units: PSNR in dB, SSIM and LPIPS unitless,
//! D-RMSE in metres, EPE3D in the export's flow units, Acc5/Acc10 as fractions (percent in the Markdown),
//! angular error in radians. A PSNR of identical images is infinite, which JSON cannot hold: it is written as
//! `null`.

use std::fmt::Write as _;
use std::path::PathBuf;

use dggt_data::Preprocess;
use dggt_infer::CheckpointInfo;
use serde::Serialize;

use crate::grid::DEPTH_EDGE_SPAN;
use crate::protocol::{Protocol, TargetKind};
use dggt_metrics::{FlowMetrics, mean_present};

/// How the predicted 3D motion was obtained.
pub const MOTION_HELD: &str = "held (no motion head)";

/// The motion source of a model that predicts velocities.
pub const MOTION_VELOCITY: &str = "predicted velocities: the expected flow (dynamic probability x velocity) of each input pixel at the input views' \
     lidar cells, in metres by the view's depth scale (least squares, no shift); at views between the inputs the \
     velocities of the assembled Gaussians rasterised and divided by the opacity";

/// The motion source of a reconstruction that moves its dynamic Gaussians along the flow head's learnt flow.
pub const MOTION_LEARNT: &str = "learnt: each dynamic pixel's displacement to the neighbouring inputs from the flow head, \
     a fraction of it at a time between them; the expected flow (dynamic probability x its displacement to the next \
     input over the step's time) of each input pixel at the input views' lidar cells, as for predicted velocities";

/// The motion source of a reconstruction that moves its objects along their trajectories.
pub const MOTION_INSTANCES: &str = "instances: the dynamic pixels grouped into objects, each moving rigidly along its \
     trajectory through the inputs; the expected flow (dynamic probability x the object's point velocity at the \
     view's time) of each input pixel at the input views' lidar cells, as for predicted velocities";

/// Metrics of one rendered target view.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViewRecord {
    /// Export frame index.
    pub frame: usize,
    /// Export camera id.
    pub camera: usize,
    pub camera_name: String,
    pub split: TargetKind,
    /// Scene time the view was rendered at (the release's timeline).
    pub scene_time: f64,
    /// PSNR in dB against the preprocessed image.
    pub psnr: f64,
    pub ssim: f64,
    /// LPIPS-Alex; absent without weights (see [`EvalReport::lpips_note`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    /// PSNR in dB over the pixels of the export's dynamic mask (moving objects); absent without a mask or
    /// with an empty one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_psnr: Option<f64>,
    /// Pixels of the dynamic mask at the network's resolution.
    pub dynamic_pixels: usize,
    /// D-RMSE in metres; absent when the view has no usable lidar cell (see `depth_note`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub d_rmse: Option<f64>,
    /// AbsRel under the same alignment as D-RMSE ([`dggt_metrics::DepthAlignment::abs_rel`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub abs_rel: Option<f64>,
    /// The alignment's scale and shift and the cells scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_shift: Option<f64>,
    pub depth_cells: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_note: Option<String>,
    /// Where the depth error lies and what the median depth scores; absent without D-RMSE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_parts: Option<DepthParts>,
    /// Scene-flow metrics of the predicted motion; absent when not evaluated (see the scene's notes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion: Option<FlowMetrics>,
    /// The same cells' scene-flow metrics under every motion source the reconstruction has (the one it
    /// renders with among them), side by side (between the inputs each rendered its way); only at views where
    /// every source is scored, and only when there is more than one source.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub motion_by_source: Vec<SourceFlowMetrics>,
    /// At a view between the inputs with moving objects in its mask, the PSNR over the mask of the view
    /// rendered under every image source the scene has ([`crate::ImageSource`]), side by side.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dynamic_psnr_by_source: Vec<SourcePsnr>,
    /// The image metrics of the render after the diffusion refiner; absent without one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refined: Option<ImageScores>,
    /// The baseline a method must beat to have learnt anything: the image metrics of the input view of the same
    /// camera nearest in time, copied unchanged (no LPIPS); absent at input views.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nearest_input: Option<ImageScores>,
}

/// The depth error's parts at one view (or their means over a split's views, or scenes): AbsRel of the expected
/// depth under the view's alignment over the lidar cells at a depth edge (the render's 3x3 neighbourhood spans
/// more than [`DEPTH_EDGE_SPAN`]) and over the rest, the share of cells at an edge, and
/// D-RMSE (m) and AbsRel of the median depth ([`dggt_scene::DepthStatistic::Median`]) under its own alignment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthParts {
    pub abs_rel_at_edges: Option<f64>,
    pub abs_rel_elsewhere: Option<f64>,
    pub edge_fraction: Option<f64>,
    pub median_d_rmse: Option<f64>,
    pub median_abs_rel: Option<f64>,
}

impl DepthParts {
    /// The means of each part over `parts` (those that have it); `None` when none has parts.
    fn mean(parts: &[Option<&DepthParts>]) -> Option<DepthParts> {
        let mean = |f: fn(&DepthParts) -> Option<f64>| mean_present(parts.iter().map(|p| p.and_then(f))).0;
        parts.iter().any(Option::is_some).then(|| DepthParts {
            abs_rel_at_edges: mean(|p| p.abs_rel_at_edges),
            abs_rel_elsewhere: mean(|p| p.abs_rel_elsewhere),
            edge_fraction: mean(|p| p.edge_fraction),
            median_d_rmse: mean(|p| p.median_d_rmse),
            median_abs_rel: mean(|p| p.median_abs_rel),
        })
    }
}

/// The scene-flow metrics of one motion source at one view.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceFlowMetrics {
    /// `held`, `velocity` or `instances`.
    pub source: String,
    #[serde(flatten)]
    pub metrics: FlowMetrics,
}

/// The PSNR (dB) over the moving objects' pixels of one image source at one view, or its mean over a split's
/// views (or scenes) with `count` of them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourcePsnr {
    /// `held`, `cross-fade`, `velocity` or `instances`.
    pub source: String,
    pub dynamic_psnr: f64,
    /// Views (or scenes) averaged; 1 for a view.
    pub count: usize,
}

/// The means of one motion source's scene-flow metrics over a split's views (or scenes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceSummary {
    pub source: String,
    pub epe3d: Option<f64>,
    pub acc5: Option<f64>,
    pub acc10: Option<f64>,
    /// EPE3D over the points that move ([`FlowMetrics::moving_epe3d`]).
    pub moving_epe3d: Option<f64>,
    pub angle_error_rad: Option<f64>,
    /// Views (or scenes) with this source's metrics.
    pub count: usize,
}

/// PSNR (dB), SSIM and LPIPS (absent without weights) of one image against the truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageScores {
    pub psnr: f64,
    pub ssim: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
}

/// Means of one split (of one scene, or over scenes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitSummary {
    pub split: TargetKind,
    /// Views of the split (per scene), or scenes (overall).
    pub count: usize,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub lpips: Option<f64>,
    /// PSNR over the moving objects' pixels, and the views (or scenes) that have some.
    pub dynamic_psnr: Option<f64>,
    pub dynamic_psnr_count: usize,
    pub d_rmse: Option<f64>,
    /// Views (or scenes) with a D-RMSE.
    pub d_rmse_count: usize,
    pub abs_rel: Option<f64>,
    /// The depth error's parts ([`ViewRecord::depth_parts`]), absent without D-RMSE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_parts: Option<DepthParts>,
    pub epe3d: Option<f64>,
    pub acc5: Option<f64>,
    pub acc10: Option<f64>,
    pub angle_error_rad: Option<f64>,
    /// Views (or scenes) with motion metrics.
    pub motion_count: usize,
    /// Every motion source's means, side by side.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub motion_by_source: Vec<SourceSummary>,
    /// Every image source's moving-object PSNR, side by side (views between the inputs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dynamic_psnr_by_source: Vec<SourcePsnr>,
    /// The image metrics after the diffusion refiner; absent without one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refined: Option<ImageMeans>,
    /// The nearest input copied ([`ViewRecord::nearest_input`]); absent in splits of input views.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nearest_input: Option<ImageMeans>,
}

/// Means of the image metrics of images scored beside the renders: the refined renders, the nearest inputs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageMeans {
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub lpips: Option<f64>,
}

/// Seconds spent in one stage.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

/// One scene's records and means.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneReport {
    pub path: PathBuf,
    pub name: String,
    pub input_frames: Vec<usize>,
    /// Network input size `[width, height]`.
    pub network_size: [u32; 2],
    pub views: Vec<ViewRecord>,
    pub splits: Vec<SplitSummary>,
    pub stages: Vec<StageTime>,
    /// Where the true scene flow the motion is scored against comes from.
    pub scene_flow: dggt_data::FlowOrigin,
    pub notes: Vec<String>,
}

/// The whole evaluation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    pub protocol: Protocol,
    pub input_frames: Vec<usize>,
    pub checkpoint: CheckpointInfo,
    /// How the inputs were prepared for the network (its input width among them).
    pub preprocess: Preprocess,
    pub device: String,
    /// Where the predicted motion comes from.
    pub motion_source: String,
    /// Where the cameras came from: the camera head's (`predicted`, the paper's unposed protocol) or the
    /// export's (`ground_truth`).
    pub poses: dggt_infer::CameraSource,
    /// What is compared for depth and motion, and how.
    pub depth_protocol: String,
    pub motion_protocol: String,
    /// Why LPIPS is absent, when it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_note: Option<String>,
    /// The diffusion refiner the renders were also scored after, when one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refiner: Option<String>,
    pub scenes: Vec<SceneReport>,
    /// Per split, the mean over scenes.
    pub overall: Vec<SplitSummary>,
    /// Summed over scenes; `load` includes the checkpoint.
    pub stages: Vec<StageTime>,
    pub warnings: Vec<String>,
}

/// Means of `views` of `split` (views of other splits are ignored).
pub fn summarise_views(views: &[ViewRecord], split: TargetKind) -> SplitSummary {
    let views: Vec<&ViewRecord> = views.iter().filter(|v| v.split == split).collect();
    let motion = |f: fn(&FlowMetrics) -> Option<f64>| mean_present(views.iter().map(|v| v.motion.as_ref().and_then(f)));
    let (d_rmse, d_rmse_count) = mean_present(views.iter().map(|v| v.d_rmse));
    let (dynamic_psnr, dynamic_psnr_count) = mean_present(views.iter().map(|v| v.dynamic_psnr));
    let (epe3d, motion_count) = motion(|m| Some(m.epe3d));
    SplitSummary {
        split,
        count: views.len(),
        psnr: mean_present(views.iter().map(|v| Some(v.psnr))).0,
        ssim: mean_present(views.iter().map(|v| Some(v.ssim))).0,
        lpips: mean_present(views.iter().map(|v| v.lpips)).0,
        dynamic_psnr,
        dynamic_psnr_count,
        d_rmse,
        d_rmse_count,
        abs_rel: mean_present(views.iter().map(|v| v.abs_rel)).0,
        depth_parts: DepthParts::mean(&views.iter().map(|v| v.depth_parts.as_ref()).collect::<Vec<_>>()),
        epe3d,
        acc5: motion(|m| Some(m.acc5)).0,
        acc10: motion(|m| Some(m.acc10)).0,
        angle_error_rad: motion(|m| m.angle_error_rad).0,
        motion_count,
        motion_by_source: source_names(views.iter().flat_map(|v| &v.motion_by_source).map(|m| &m.source))
            .into_iter()
            .map(|source| {
                let of_source = |v: &&ViewRecord| v.motion_by_source.iter().find(|m| m.source == source).cloned();
                let metrics: Vec<FlowMetrics> = views.iter().filter_map(of_source).map(|m| m.metrics).collect();
                let mean = |f: fn(&FlowMetrics) -> Option<f64>| mean_present(metrics.iter().map(f));
                SourceSummary {
                    source,
                    epe3d: mean(|m| Some(m.epe3d)).0,
                    acc5: mean(|m| Some(m.acc5)).0,
                    acc10: mean(|m| Some(m.acc10)).0,
                    moving_epe3d: mean(|m| m.moving_epe3d).0,
                    angle_error_rad: mean(|m| m.angle_error_rad).0,
                    count: metrics.len(),
                }
            })
            .collect(),
        dynamic_psnr_by_source: mean_by_source(
            &views.iter().flat_map(|v| &v.dynamic_psnr_by_source).collect::<Vec<_>>(),
        ),
        refined: view_means(&views, |v| v.refined.as_ref()),
        nearest_input: view_means(&views, |v| v.nearest_input.as_ref()),
    }
}

/// The means of the scores `of` picks from each view, when some view has them.
fn view_means(views: &[&ViewRecord], of: fn(&ViewRecord) -> Option<&ImageScores>) -> Option<ImageMeans> {
    views.iter().any(|v| of(v).is_some()).then(|| {
        let mean = |f: fn(&ImageScores) -> Option<f64>| mean_present(views.iter().map(|v| of(v).and_then(f))).0;
        ImageMeans { psnr: mean(|r| Some(r.psnr)), ssim: mean(|r| Some(r.ssim)), lpips: mean(|r| r.lpips) }
    })
}

/// The means over scenes of the split means `of` picks, when some scene has them.
fn split_means(rows: &[&SplitSummary], of: fn(&SplitSummary) -> Option<&ImageMeans>) -> Option<ImageMeans> {
    rows.iter().any(|r| of(r).is_some()).then(|| {
        let mean = |f: fn(&ImageMeans) -> Option<f64>| mean_present(rows.iter().map(|r| of(r).and_then(f))).0;
        ImageMeans { psnr: mean(|r| r.psnr), ssim: mean(|r| r.ssim), lpips: mean(|r| r.lpips) }
    })
}

/// Per split, the mean over the scenes' split means.
pub fn summarise_scenes(scenes: &[SceneReport], splits: &[TargetKind]) -> Vec<SplitSummary> {
    splits
        .iter()
        .map(|&split| {
            let rows: Vec<&SplitSummary> =
                scenes.iter().flat_map(|s| s.splits.iter().filter(|r| r.split == split)).collect();
            let mean = |f: fn(&SplitSummary) -> Option<f64>| mean_present(rows.iter().map(|r| f(r)));
            SplitSummary {
                split,
                count: rows.len(),
                psnr: mean(|r| r.psnr).0,
                ssim: mean(|r| r.ssim).0,
                lpips: mean(|r| r.lpips).0,
                dynamic_psnr: mean(|r| r.dynamic_psnr).0,
                dynamic_psnr_count: mean(|r| r.dynamic_psnr).1,
                d_rmse: mean(|r| r.d_rmse).0,
                d_rmse_count: mean(|r| r.d_rmse).1,
                abs_rel: mean(|r| r.abs_rel).0,
                depth_parts: DepthParts::mean(&rows.iter().map(|r| r.depth_parts.as_ref()).collect::<Vec<_>>()),
                epe3d: mean(|r| r.epe3d).0,
                acc5: mean(|r| r.acc5).0,
                acc10: mean(|r| r.acc10).0,
                angle_error_rad: mean(|r| r.angle_error_rad).0,
                motion_count: mean(|r| r.epe3d).1,
                motion_by_source: source_names(rows.iter().flat_map(|r| &r.motion_by_source).map(|m| &m.source))
                    .into_iter()
                    .map(|source| {
                        let of_source: Vec<&SourceSummary> = rows
                            .iter()
                            .filter_map(|r| r.motion_by_source.iter().find(|m| m.source == source))
                            .collect();
                        let mean = |f: fn(&SourceSummary) -> Option<f64>| mean_present(of_source.iter().map(|m| f(m)));
                        SourceSummary {
                            source,
                            epe3d: mean(|m| m.epe3d).0,
                            acc5: mean(|m| m.acc5).0,
                            acc10: mean(|m| m.acc10).0,
                            moving_epe3d: mean(|m| m.moving_epe3d).0,
                            angle_error_rad: mean(|m| m.angle_error_rad).0,
                            count: mean(|m| m.epe3d).1,
                        }
                    })
                    .collect(),
                dynamic_psnr_by_source: mean_by_source(
                    &rows.iter().flat_map(|r| &r.dynamic_psnr_by_source).collect::<Vec<_>>(),
                ),
                refined: split_means(&rows, |r| r.refined.as_ref()),
                nearest_input: split_means(&rows, |r| r.nearest_input.as_ref()),
            }
        })
        .collect()
}

/// Per source (in order of first appearance), the mean of its PSNRs among `scores` and how many there are.
fn mean_by_source(scores: &[&SourcePsnr]) -> Vec<SourcePsnr> {
    source_names(scores.iter().map(|s| &s.source))
        .into_iter()
        .map(|source| {
            let (mean, count) =
                mean_present(scores.iter().filter(|s| s.source == source).map(|s| Some(s.dynamic_psnr)));
            SourcePsnr { source, dynamic_psnr: mean.unwrap_or(f64::NAN), count }
        })
        .collect()
}

/// The distinct source names among `names`, in order of first appearance.
fn source_names<'a>(names: impl Iterator<Item = &'a String>) -> Vec<String> {
    let mut distinct: Vec<String> = Vec::new();
    for name in names {
        if !distinct.contains(name) {
            distinct.push(name.clone());
        }
    }
    distinct
}

fn cell(value: Option<f64>, digits: usize) -> String {
    value.map_or_else(|| "-".into(), |v| format!("{v:.digits$}"))
}

fn percent(value: Option<f64>) -> String {
    value.map_or_else(|| "-".into(), |v| format!("{:.2}", 100.0 * v))
}

fn row(label: &str, count: &str, s: &SplitSummary) -> String {
    format!(
        "| {label} | {count} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
        cell(s.psnr, 2),
        cell(s.ssim, 4),
        cell(s.lpips, 4),
        cell(s.dynamic_psnr, 2),
        cell(s.d_rmse, 3),
        cell(s.abs_rel, 3),
        cell(s.epe3d, 3),
        percent(s.acc5),
        percent(s.acc10),
        cell(s.angle_error_rad, 3),
    )
}

impl EvalReport {
    /// The table of one split's renders beside other images (`other` of each scene's split and of the mean),
    /// under `heading`, their columns labelled `label`.
    fn paired_table(
        &self,
        heading: &str,
        label: &str,
        summary: &SplitSummary,
        scenes: &str,
        other: OtherImages,
    ) -> String {
        let mut md = format!(
            "\n### {heading}\n\n| scene | views | PSNR (dB) | PSNR {label} | SSIM | SSIM {label} | LPIPS | LPIPS {label} |\n\
             |---|---|---|---|---|---|---|---|\n"
        );
        for scene in &self.scenes {
            if let Some(s) = scene.splits.iter().find(|s| s.split == summary.split) {
                md.push_str(&paired_row(&scene.name, &s.count.to_string(), s, other(s)));
            }
        }
        md.push_str(&paired_row("**mean over scenes**", scenes, summary, other(summary)));
        md
    }
}

impl EvalReport {
    /// The table of one split's depth error parts: each scene's and the mean over scenes.
    fn depth_parts_table(&self, summary: &SplitSummary, scenes: &str) -> String {
        let mut md = format!(
            "\n### depth at depth edges (3x3 span > {DEPTH_EDGE_SPAN}) and elsewhere; the median depth\n\n\
             | scene | views | AbsRel | AbsRel at edges | AbsRel elsewhere | cells at edges (%) | median D-RMSE (m) | \
             median AbsRel |\n|---|---|---|---|---|---|---|---|\n"
        );
        let rows = self.scenes.iter().filter_map(|scene| {
            let s = scene.splits.iter().find(|s| s.split == summary.split)?;
            Some((scene.name.as_str(), s.count.to_string(), s))
        });
        for (label, count, s) in rows.chain([("**mean over scenes**", scenes.to_string(), summary)]) {
            let parts = s.depth_parts.as_ref();
            let _ = writeln!(
                md,
                "| {label} | {count} | {} | {} | {} | {} | {} | {} |",
                cell(s.abs_rel, 3),
                cell(parts.and_then(|p| p.abs_rel_at_edges), 3),
                cell(parts.and_then(|p| p.abs_rel_elsewhere), 3),
                percent(parts.and_then(|p| p.edge_fraction)),
                cell(parts.and_then(|p| p.median_d_rmse), 3),
                cell(parts.and_then(|p| p.median_abs_rel), 3),
            );
        }
        md
    }
}

/// Picks, from a split's means, those of images scored beside the renders.
type OtherImages = fn(&SplitSummary) -> Option<&ImageMeans>;

/// A row of a table of the renders beside other images (`other`: the refined renders, the nearest inputs).
fn paired_row(label: &str, count: &str, s: &SplitSummary, other: Option<&ImageMeans>) -> String {
    format!(
        "| {label} | {count} | {} | {} | {} | {} | {} | {} |\n",
        cell(s.psnr, 2),
        cell(other.and_then(|r| r.psnr), 2),
        cell(s.ssim, 4),
        cell(other.and_then(|r| r.ssim), 4),
        cell(s.lpips, 4),
        cell(other.and_then(|r| r.lpips), 4),
    )
}

impl EvalReport {
    /// The report as Markdown: settings, one table per split (a row per scene and the mean over scenes),
    /// then the notes and stage times.
    pub fn markdown(&self) -> String {
        let mut md = String::new();
        let p = &self.protocol;
        let _ = writeln!(md, "# dggt eval: {} protocol\n", p.kind);
        let _ = writeln!(
            md,
            "- window: frames {}..{} (end exclusive), cameras {:?}; inputs: frames {:?}",
            p.start,
            p.start + p.length,
            p.cameras,
            self.input_frames
        );
        let _ = writeln!(md, "- checkpoint: {} ({})", self.checkpoint.path.display(), self.checkpoint.format);
        let _ = writeln!(md, "- device: {}", self.device);
        let _ = writeln!(md, "- motion source: {}", self.motion_source);
        let _ = writeln!(
            md,
            "- cameras: {}",
            match self.poses {
                dggt_infer::CameraSource::Predicted =>
                    "predicted by the camera head, targets interpolated between the inputs (unposed)",
                dggt_infer::CameraSource::GroundTruth => "the export's poses, relative to the first input view",
            }
        );
        let _ = writeln!(md, "- depth: {}", self.depth_protocol);
        let _ = writeln!(md, "- motion: {}", self.motion_protocol);
        for scene in &self.scenes {
            let _ = writeln!(md, "- true scene flow of {}: {}", scene.name, scene.scene_flow.describe());
        }
        if let Some(note) = &self.lpips_note {
            let _ = writeln!(md, "- LPIPS: {note}");
        }
        if let Some(refiner) = &self.refiner {
            let _ = writeln!(md, "- refiner: {refiner}");
        }
        for summary in &self.overall {
            let _ = writeln!(md, "\n## {}\n", summary.split.title());
            md.push_str(
                "| scene | views | PSNR (dB) | SSIM | LPIPS | moving PSNR (dB) | D-RMSE (m) | AbsRel | EPE3D | Acc5 (%) | \
                 Acc10 (%) | angle (rad) |\n",
            );
            md.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
            for scene in &self.scenes {
                if let Some(s) = scene.splits.iter().find(|s| s.split == summary.split) {
                    md.push_str(&row(&scene.name, &s.count.to_string(), s));
                }
            }
            let scenes = if summary.count == 1 { "1 scene".to_string() } else { format!("{} scenes", summary.count) };
            md.push_str(&row("**mean over scenes**", &scenes, summary));
            if summary.depth_parts.is_some() {
                md.push_str(&self.depth_parts_table(summary, &scenes));
            }
            if !summary.motion_by_source.is_empty() {
                md.push_str("\n### motion by source (mean over scenes)\n\n");
                md.push_str(
                    "| source | scenes | EPE3D | EPE3D moving | Acc5 (%) | Acc10 (%) | angle (rad) |\n\
                     |---|---|---|---|---|---|---|\n",
                );
                for source in &summary.motion_by_source {
                    let _ = writeln!(
                        md,
                        "| {} | {} | {} | {} | {} | {} | {} |",
                        source.source,
                        source.count,
                        cell(source.epe3d, 3),
                        cell(source.moving_epe3d, 3),
                        percent(source.acc5),
                        percent(source.acc10),
                        cell(source.angle_error_rad, 3)
                    );
                }
            }
            if !summary.dynamic_psnr_by_source.is_empty() {
                md.push_str("\n### moving objects between the inputs by source (mean over scenes)\n\n");
                md.push_str("| source | scenes | moving PSNR (dB) |\n|---|---|---|\n");
                for source in &summary.dynamic_psnr_by_source {
                    let _ = writeln!(md, "| {} | {} | {:.2} |", source.source, source.count, source.dynamic_psnr);
                }
            }
            let pairs: [(&str, &str, OtherImages); 2] = [
                ("without and with the refiner", "refined", |s| s.refined.as_ref()),
                ("the renders against the nearest input copied (the baseline to beat)", "copied", |s| {
                    s.nearest_input.as_ref()
                }),
            ];
            for (heading, label, other) in pairs {
                if other(summary).is_some() {
                    md.push_str(&self.paired_table(heading, label, summary, &scenes, other));
                }
            }
        }
        let notes: Vec<String> = self
            .scenes
            .iter()
            .flat_map(|s| s.notes.iter().map(move |n| format!("{}: {n}", s.name)))
            .chain(self.warnings.iter().cloned())
            .collect();
        if !notes.is_empty() {
            md.push_str("\n## notes\n\n");
            for note in notes {
                let _ = writeln!(md, "- {note}");
            }
        }
        md.push_str("\n## time per stage\n\n| stage | seconds |\n|---|---|\n");
        for stage in &self.stages {
            let _ = writeln!(md, "| {} | {:.2} |", stage.stage, stage.seconds);
        }
        md
    }
}
