//! A `dggt reconstruct` output folder logged as a rerun recording (see the crate's doc for the conventions).
//!
//! Entities: `world` (its axes); `world/camera_C` (transform and pinhole of rig camera `C` at each of its input
//! times) with `image`, `depth`, `dynamic`, `sky` and, at the rendered times, `render`; `world/gaussians/static`
//! and `world/gaussians/sky` (static), `world/gaussians/dynamic` (at each rendered time); `world/instances/ID`
//! (the object's box at each input time it was seen) with `trajectory` (static); `summary` (a text document).

use std::path::{Path, PathBuf};
use std::time::Instant;

use dggt_formats::cameras_json::{CameraRecord, read_cameras_json};
use dggt_formats::depth::read_depth_npy;
use dggt_formats::images::read_rgb_png;
use dggt_formats::masks::read_mask_png;
use dggt_formats::ply::read_ply;
use serde::Deserialize;

use crate::components::{camera_transform, depth_image, grey_image, part_tabs, pinhole, rgb_image};
use crate::error::RerunError;
use crate::splats::splats;

/// Log frames per second (the project's convention: 10 Hz logs).
const FRAMES_PER_SECOND: f64 = 10.0;

/// What was recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingReport {
    pub path: PathBuf,
    pub bytes: u64,
    pub seconds: f64,
    /// `(time in seconds, dynamic splats)` per rendered time.
    pub dynamic_splats: Vec<(f64, usize)>,
    pub static_splats: usize,
    pub cameras: usize,
}

/// The parts of `summary.json` the recording shows.
#[derive(Debug, Deserialize)]
struct SummaryFile {
    times_s: Vec<f64>,
    #[serde(default)]
    renders: Vec<RenderFile>,
    #[serde(default)]
    instances: Vec<InstanceFile>,
}

#[derive(Debug, Deserialize)]
struct RenderFile {
    file: String,
    camera: usize,
    time_s: f64,
}

#[derive(Debug, Deserialize)]
struct InstanceFile {
    id: u32,
    appearances: Vec<AppearanceFile>,
}

#[derive(Debug, Deserialize)]
struct AppearanceFile {
    frame: usize,
    box_min: [f64; 3],
    box_max: [f64; 3],
    centre: [f64; 3],
}

/// Writes the reconstruction in `folder` as a recording at `rrd` (replacing nothing: the caller checks).
pub fn record_reconstruction(folder: &Path, rrd: &Path) -> Result<RecordingReport, RerunError> {
    let started = Instant::now();
    let summary_path = folder.join("summary.json");
    let text = std::fs::read(&summary_path)
        .map_err(|e| RerunError::Input { path: summary_path.clone(), detail: e.to_string() })?;
    let summary: SummaryFile = serde_json::from_slice(&text).map_err(|e| RerunError::Input {
        path: summary_path.clone(),
        detail: format!("not a reconstruction summary: {e}"),
    })?;
    let (_, cameras) = read_cameras_json(&folder.join("cameras.json"))?;
    let recording_error = |e: &dyn std::fmt::Display| RerunError::Recording { path: rrd.into(), detail: e.to_string() };
    let mut rig: Vec<usize> = cameras.iter().map(|c| c.camera).collect();
    rig.sort_unstable();
    rig.dedup();
    let recording = rerun::RecordingStreamBuilder::new("dggt_reconstruction")
        .with_blueprint(layout(&rig))
        .save(rrd)
        .map_err(|e| recording_error(&e))?;
    let log = Logger { recording: &recording, folder, first_frame: cameras.iter().map(|c| c.frame).min().unwrap_or(0) };
    log.statics(&String::from_utf8_lossy(&text)).map_err(|e| recording_error(&e))?;
    for camera in &cameras {
        log.camera(camera)?;
    }
    let static_splats = log.gaussians_once()?;
    let mut dynamic_splats = Vec::new();
    for (k, &time) in summary.times_s.iter().enumerate() {
        log.at(time);
        let path = folder.join(format!("gaussians/dynamic_t{k:04}.ply"));
        let count = log.cloud("world/gaussians/dynamic", &path)?;
        dynamic_splats.push((time, count));
    }
    for render in &summary.renders {
        log.at(render.time_s);
        let (size, rgb) = read_rgb_png(&folder.join(&render.file))?;
        log.send(&format!("world/camera_{}/render", render.camera), &rgb_image(size, &rgb))?;
    }
    log.instances(&summary.instances, &cameras)?;
    recording.flush_blocking().map_err(|e| recording_error(&e))?;
    drop(recording);
    let bytes = std::fs::metadata(rrd).map_err(|e| recording_error(&e))?.len();
    Ok(RecordingReport {
        path: rrd.into(),
        bytes,
        seconds: started.elapsed().as_secs_f64(),
        dynamic_splats,
        static_splats,
        cameras: cameras.len(),
    })
}

/// Logs into one recording from one folder.
struct Logger<'a> {
    recording: &'a rerun::RecordingStream,
    folder: &'a Path,
    first_frame: usize,
}

impl Logger<'_> {
    /// Sets both time lines to `time_s` seconds since the first chosen frame.
    fn at(&self, time_s: f64) {
        self.recording.set_duration_secs("time", time_s);
        let frame = self.first_frame as f64 + (time_s * FRAMES_PER_SECOND).round();
        self.recording.set_time_sequence("frame", frame as i64);
    }

    fn send(&self, entity: &str, data: &impl rerun::AsComponents) -> Result<(), RerunError> {
        self.recording
            .log(entity, data)
            .map_err(|e| RerunError::Entity { entity: entity.into(), detail: e.to_string() })
    }

    fn send_static(&self, entity: &str, data: &impl rerun::AsComponents) -> Result<(), RerunError> {
        self.recording
            .log_static(entity, data)
            .map_err(|e| RerunError::Entity { entity: entity.into(), detail: e.to_string() })
    }

    /// The world's axes and the summary as text.
    fn statics(&self, summary: &str) -> Result<(), RerunError> {
        self.send_static("world", &rerun::ViewCoordinates::RDF())?;
        self.send_static(
            "summary",
            &rerun::TextDocument::new(format!("```json\n{summary}\n```")).with_media_type(rerun::MediaType::markdown()),
        )
    }

    /// One input view: its camera's pose and pinhole, image, depth and masks, at its time.
    fn camera(&self, camera: &CameraRecord) -> Result<(), RerunError> {
        self.at(camera.time_s);
        let entity = format!("world/camera_{}", camera.camera);
        self.send(&entity, &camera_transform(&camera.world_from_camera))?;
        self.send(&entity, &pinhole(&camera.intrinsics, camera.size))?;
        let file =
            |folder: &str, extension: &str| self.folder.join(folder).join(format!("{}.{extension}", camera.name));
        let (size, rgb) = read_rgb_png(&file("images", "png"))?;
        self.send(&format!("{entity}/image"), &rgb_image(size, &rgb))?;
        let (size, depth) = read_depth_npy(&file("depth", "npy"))?;
        self.send(&format!("{entity}/depth"), &depth_image(size, &depth))?;
        for mask in ["dynamic", "sky"] {
            let path = file(mask, "png");
            if path.is_file() {
                let (size, values) = read_mask_png(&path)?;
                self.send(&format!("{entity}/{mask}"), &grey_image(size, &values))?;
            }
        }
        Ok(())
    }

    /// The static and sky Gaussians, once; returns how many static ones.
    fn gaussians_once(&self) -> Result<usize, RerunError> {
        let statics = self.cloud_static("world/gaussians/static", &self.folder.join("gaussians/static.ply"))?;
        let sky = self.folder.join("gaussians/sky.ply");
        if sky.is_file() {
            self.cloud_static("world/gaussians/sky", &sky)?;
        }
        Ok(statics)
    }

    fn cloud_static(&self, entity: &str, path: &Path) -> Result<usize, RerunError> {
        let cloud = read_cloud(path)?;
        self.send_static(entity, &splats(&cloud))?;
        Ok(cloud.len())
    }

    /// The cloud at `path` logged at the current time; returns its size.
    fn cloud(&self, entity: &str, path: &Path) -> Result<usize, RerunError> {
        let cloud = read_cloud(path)?;
        self.send(entity, &splats(&cloud))?;
        Ok(cloud.len())
    }

    /// Each object's box at the input times it was seen, and its trajectory through its centres.
    fn instances(&self, instances: &[InstanceFile], cameras: &[CameraRecord]) -> Result<(), RerunError> {
        for instance in instances {
            let entity = format!("world/instances/{}", instance.id);
            for appearance in &instance.appearances {
                let time = cameras.iter().find(|c| c.frame == appearance.frame).map_or_else(
                    || (appearance.frame as f64 - self.first_frame as f64) / FRAMES_PER_SECOND,
                    |camera| camera.time_s,
                );
                self.at(time);
                let min = appearance.box_min.map(|v| v as f32);
                let size: [f32; 3] = std::array::from_fn(|k| (appearance.box_max[k] - appearance.box_min[k]) as f32);
                let label = format!("instance {}", instance.id);
                self.send(&entity, &rerun::Boxes3D::from_mins_and_sizes([min], [size]).with_labels([label]))?;
            }
            let centres: Vec<[f32; 3]> = instance.appearances.iter().map(|a| a.centre.map(|v| v as f32)).collect();
            self.send_static(&format!("{entity}/trajectory"), &rerun::LineStrips3D::new([centres]))?;
        }
        Ok(())
    }
}

/// The default layout: the 3D scene beside, per camera, tabs of its image, render, depth and masks; the
/// summary below.
fn layout(cameras: &[usize]) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{Blueprint, ContainerLike, Horizontal, Spatial3DView, TextDocumentView, Vertical};
    let camera_tabs = |camera: usize| {
        part_tabs(
            &format!("camera {camera}"),
            &format!("world/camera_{camera}"),
            &["image", "render", "depth", "dynamic", "sky"],
        )
    };
    let scene: ContainerLike = Spatial3DView::new("scene").with_origin("world").into();
    let cameras: ContainerLike = Vertical::new(cameras.iter().map(|&c| camera_tabs(c))).into();
    let summary: ContainerLike = TextDocumentView::new("summary").with_origin("summary").into();
    let top: ContainerLike = Horizontal::new([scene, cameras]).with_column_shares([2.0, 1.0]).into();
    Blueprint::new(Vertical::new([top, summary]).with_row_shares([4.0, 1.0]))
}

fn read_cloud(path: &Path) -> Result<dggt_formats::ply::GaussianCloud, RerunError> {
    read_ply(path)?.to_cloud().map_err(|e| RerunError::Input { path: path.into(), detail: e.to_string() })
}
