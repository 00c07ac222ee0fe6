//! The edited scene written out: for every chosen camera and time the edited render, the render before and
//! after side by side, and the mask of its holes (pixels the edit uncovered where nothing was seen behind:
//! foreground opacity at least one half before the edit, below one half after it); per time the Gaussians the
//! edited scene draws for the first chosen camera (culled to its view), as an INRIA-layout PLY; and `edit.json` listing what was done and written.
//!
//! Output folder layout (`NNNN` the position of the time, `C` the rig camera):
//! `renders/tNNNN_camC.png`, `before_after/tNNNN_camC.png`, `holes/tNNNN_camC.png`, `gaussians/tNNNN.ply`,
//! `edit.json`.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_formats::images::write_rgb_png;
use dggt_formats::masks::write_binary_png;
use dggt_formats::ply::write_ply;
use dggt_geom::ImageSize;
use dggt_model::host::host_f32;
use dggt_scene::{AssembledGaussians, Scene4d, TargetView, load_scene};
use serde::Serialize;

use crate::apply::{EditedScene, apply_edits};
use crate::error::EditError;
use crate::object::cloud_of;
use crate::request::Edit;

/// What `dggt edit` is asked.
#[derive(Debug, Clone)]
pub struct EditOptions {
    /// A reconstruction folder (its `scene.safetensors`) or the file itself.
    pub scene: PathBuf,
    pub edits: Vec<Edit>,
    /// Rig cameras to render; `None`: every camera of the scene.
    pub cameras: Option<Vec<usize>>,
    /// Scene times to render; `None`: the input views' times.
    pub times: Option<Vec<f64>>,
}

/// A checked edit job: the scene loaded and edited, the cameras and times valid. Nothing is written until
/// [`EditJob::write`].
#[derive(Debug, Clone)]
pub struct EditJob {
    pub scene_file: PathBuf,
    pub edits: Vec<Edit>,
    pub scene: EditedScene,
    pub cameras: Vec<usize>,
    pub times: Vec<f64>,
}

/// What was edited and written, as `edit.json` holds it.
#[derive(Debug, Clone, Serialize)]
pub struct EditSummary {
    pub scene: PathBuf,
    pub edits: Vec<String>,
    /// `[x, y, z]` of the world's up axis that yaws turn about.
    pub up: [f64; 3],
    pub renders: Vec<EditedRender>,
    pub files: Vec<String>,
}

/// One edited view.
#[derive(Debug, Clone, Serialize)]
pub struct EditedRender {
    pub time: f64,
    pub camera: usize,
    pub file: String,
    /// Pixels whose colour the edit changed by more than one 8-bit level in some channel.
    pub changed_pixels: usize,
    /// Pixels the edit uncovered with nothing seen behind them.
    pub hole_pixels: usize,
}

/// The first write of [`write_edits`]: loads, edits and checks everything.
pub fn prepare_edits(options: &EditOptions, device: &Device) -> Result<EditJob, EditError> {
    let scene_file = dggt_scene::scene_file(&options.scene);
    let scene: Scene4d = load_scene(&scene_file, device)?;
    let mut rig: Vec<usize> = scene.views().iter().map(|view| view.rig_camera).collect();
    rig.sort_unstable();
    rig.dedup();
    let cameras = options.cameras.clone().unwrap_or_else(|| rig.clone());
    if let Some(camera) = cameras.iter().find(|camera| !rig.contains(camera)) {
        return Err(EditError::argument("--cameras", format!("camera {camera} is not among the scene's {rig:?}")));
    }
    let mut times = options.times.clone().unwrap_or_else(|| scene.views().iter().map(|view| view.time).collect());
    if let Some(time) = times.iter().find(|time| !time.is_finite()) {
        return Err(EditError::argument("--times", format!("{time} is not a finite scene time")));
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    let scene = apply_edits(scene, &options.edits, device)?;
    Ok(EditJob { scene_file, edits: options.edits.clone(), scene, cameras, times })
}

/// Loads, edits and writes everything into `out` (an existing, empty folder or a new one).
pub fn write_edits(options: &EditOptions, out: &Path, device: &Device) -> Result<EditSummary, EditError> {
    prepare_edits(options, device)?.write(out)
}

/// Bytes per Gaussian in a PLY file (INRIA layout, float32 properties).
const PLY_VERTEX_BYTES: u64 = dggt_formats::ply::INRIA_PROPERTIES.len() as u64 * 4;
/// Bytes per pixel of one edited view's images at most (raw): the render, the side-by-side pair, the mask.
const VIEW_BYTES_PER_PIXEL: u64 = 3 + 6 + 1;

impl EditJob {
    /// The most the outputs could take: per time every Gaussian of the scene and of the inserted objects in a
    /// PLY, per view its images uncompressed.
    pub fn largest_output_bytes(&self) -> u64 {
        let gaussians =
            (self.scene.edited.pixels.len() + self.scene.carried.iter().map(|o| o.largest()).sum::<usize>()) as u64;
        let pixels = self.scene.edited.pixels.size.area() as u64;
        let (times, cameras) = (self.times.len() as u64, self.cameras.len() as u64);
        times.saturating_mul(gaussians * PLY_VERTEX_BYTES + cameras * pixels * VIEW_BYTES_PER_PIXEL)
    }

    /// Writes the renders, images, masks, PLYs and `edit.json` into `out`.
    pub fn write(&self, out: &Path) -> Result<EditSummary, EditError> {
        let mut files = Vec::new();
        let mut path = |relative: String| -> Result<PathBuf, EditError> {
            let path = out.join(&relative);
            let parent = path.parent().expect("files lie in folders");
            std::fs::create_dir_all(parent).map_err(|source| EditError::Io { path: parent.into(), source })?;
            files.push(relative);
            Ok(path)
        };
        let mut renders = Vec::new();
        for (k, &time) in self.times.iter().enumerate() {
            for (c, &camera) in self.cameras.iter().enumerate() {
                let target =
                    TargetView { rig_camera: camera, time, camera: self.scene.edited.camera_at(camera, time)? };
                let assembled = self.scene.gaussians(&target)?;
                if c == 0 {
                    write_ply(&path(format!("gaussians/t{k:04}.ply"))?, &cloud_of(&assembled.gaussians)?)?;
                }
                let view = ViewPair::render(&self.scene, &assembled, &target)?;
                let name = format!("t{k:04}_cam{camera}.png");
                write_rgb_png(&path(format!("renders/{name}"))?, view.size, &view.after)?;
                write_rgb_png(&path(format!("before_after/{name}"))?, doubled_width(view.size), &view.side_by_side())?;
                let holes = view.holes();
                write_binary_png(&path(format!("holes/{name}"))?, view.size, &holes)?;
                renders.push(EditedRender {
                    time,
                    camera,
                    file: format!("renders/{name}"),
                    changed_pixels: view.changed_pixels(),
                    hole_pixels: holes.iter().filter(|&&hole| hole).count(),
                });
            }
        }
        files.push("edit.json".into());
        let summary = EditSummary {
            scene: self.scene_file.clone(),
            edits: self.edits.iter().map(|edit| edit.argument.clone()).collect(),
            up: self.scene.up.direction().to_array(),
            renders,
            files,
        };
        let json = out.join("edit.json");
        let text = serde_json::to_string_pretty(&summary).expect("summaries serialise");
        std::fs::write(&json, text).map_err(|source| EditError::Io { path: json, source })?;
        Ok(summary)
    }
}

/// One view rendered before and after the edits (host copies, colours interleaved).
struct ViewPair {
    size: ImageSize,
    before: Vec<f32>,
    after: Vec<f32>,
    alpha_before: Vec<f32>,
    alpha_after: Vec<f32>,
}

/// Two images side by side.
fn doubled_width(size: ImageSize) -> ImageSize {
    ImageSize::new(size.width * 2, size.height).expect("a valid size doubled is valid")
}

impl ViewPair {
    /// `target` before the edits, and after them from the edited Gaussians `assembled` for it.
    fn render(scene: &EditedScene, assembled: &AssembledGaussians, target: &TargetView) -> Result<Self, EditError> {
        let before = scene.original.render(target)?;
        let after = scene.edited.render_assembled(assembled, target)?;
        let clamp = |values: Vec<f32>| values.into_iter().map(|v| v.clamp(0.0, 1.0)).collect::<Vec<f32>>();
        Ok(Self {
            size: scene.original.pixels.size,
            before: clamp(host_f32(before.rgb, "render before")?),
            after: clamp(host_f32(after.rgb, "render after")?),
            alpha_before: host_f32(before.alpha, "opacity before")?,
            alpha_after: host_f32(after.alpha, "opacity after")?,
        })
    }

    fn side_by_side(&self) -> Vec<f32> {
        let row = self.size.width as usize * 3;
        self.before.chunks_exact(row).zip(self.after.chunks_exact(row)).flat_map(|(b, a)| [b, a].concat()).collect()
    }

    fn holes(&self) -> Vec<bool> {
        self.alpha_before.iter().zip(&self.alpha_after).map(|(&b, &a)| b >= 0.5 && a < 0.5).collect()
    }

    fn changed_pixels(&self) -> usize {
        let level = 1.0 / 255.0;
        self.before
            .chunks_exact(3)
            .zip(self.after.chunks_exact(3))
            .filter(|(b, a)| b.iter().zip(a.iter()).any(|(x, y)| (x - y).abs() > level))
            .count()
    }
}
