//! The reconstruction: inputs -> one forward pass -> cameras, depth, dynamic and sky maps, Gaussians and
//! renders on disk, with a [`Summary`].
//!
//! Output folder layout (every per-view file is named `{frame:03}_{camera}`):
//! - `images/`: the inputs as the network saw them (preprocessed); all intrinsics refer to this resolution;
//! - `cameras.json` (OpenCV, both pose directions, states its convention), `sparse/0/` (COLMAP text, so the
//!   output folder is a COLMAP project with `images/`), `transforms.json` (nerfstudio, OpenGL axes);
//! - `depth/NAME.npy` (float32) and `depth/NAME.png` + `depth/NAME.json` (16-bit, one scale for all views);
//! - `dynamic/NAME.png` (dynamic probability), `sky/NAME.png` (255 where the re-rendered foreground opacity is
//!   below one half, i.e. the sky shows through);
//! - `gaussians/static.ply` (every input pixel's static part, unfaded), `gaussians/sky.ply`,
//!   `gaussians/dynamic_tNNNN.ply` (the dynamic part shown at requested time `NNNN`: each camera's nearest input
//!   view, as the renders use it);
//! - `renders/tNNNN_camC.png` at the requested times (cameras interpolated between input views);
//! - `scene.safetensors`: the whole 4D scene (every input pixel's Gaussian, the sky, the cameras and the moving
//!   objects with their trajectories; [`dggt_scene::saved`]), which renders and edits without the network
//!   (`dggt edit`);
//! - `summary.json`.
//!
//! The world is the first input view's camera frame (view 0: first frame, first camera); distances are in
//! the network's units (up to scale).

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::PlanarImage;
use dggt_formats::cameras_json::{CameraRecord, Convention, write_cameras_json};
use dggt_formats::colmap::{ColmapCamera, ColmapImage, write_colmap};
use dggt_formats::depth::{scale_for, write_depth_npy, write_depth_png16};
use dggt_formats::images::write_rgb_png;
use dggt_formats::masks::{write_binary_png, write_probability_png};
use dggt_formats::nerfstudio::{NerfstudioFrame, write_transforms};
use dggt_formats::ply::{GaussianCloud, write_ply};
use dggt_geom::{ImageSize, PosedCamera, WorldFromCamera};
use dggt_infer::{
    InputCameras, InputSet, MotionPath, SceneOptions, ViewSlot, forward_chunked, input_views, load_network,
};
use dggt_model::host::host_f32;
use dggt_run::compute_pool::on_pool_worker;
use dggt_run::progress::{Visibility, styled_bar};
use dggt_scene::{
    AssemblyCounts, AssemblySettings, InputView, Instances, MIN_OPACITY, PixelGaussians, SCENE_FILE, Scene4d,
    TargetView, Timeline, nearest_in_time, nearest_view, save_scene,
};

use crate::align::pose_error;
use crate::error::ReconstructError;
use crate::finite;
use crate::summary::{
    GaussianCounts, InstanceAppearance, InstanceRecord, RenderRecord, StageTime, Summary, peak_memory_mib,
};
use crate::times::{check_every, check_times};
use crate::volume::{DEFAULT_MAX_OUTPUT_BYTES, OutputEstimate};

/// Which times to render (and export dynamic Gaussians at).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum TimeRequest {
    /// The input frames' times.
    #[default]
    Inputs,
    /// These times, seconds since the first chosen frame, within the input frames' times.
    Seconds(Vec<f64>),
    /// `K` evenly spaced times per interval between consecutive input frames (1 = the input times).
    Every(usize),
}

/// Everything a reconstruction is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct ReconstructOptions {
    /// A folder of images (or of per-camera folders), or a scene export.
    pub images: PathBuf,
    pub checkpoint: PathBuf,
    /// Architecture of `.pt` / `.safetensors` checkpoints (default: the `dggt` preset).
    pub architecture: Option<dggt_infer::Architecture>,
    /// Camera positions (folders) or ids (exports).
    pub cameras: Option<Vec<usize>>,
    /// Frame positions (folders) or indices (exports), end exclusive.
    pub frames: Option<Range<usize>>,
    pub times: TimeRequest,
    /// Network input width (a multiple of 14); default: the width the network was trained at (recorded in a
    /// trainer checkpoint, or the `--config` training file's), else 518.
    pub width: Option<u32>,
    /// Frames per chunk of the dense heads.
    pub chunk_frames: usize,
    pub out: PathBuf,
    /// Whether the rendering progress bar is drawn on stderr.
    pub progress: Visibility,
    /// The most the outputs may take at most ([`OutputEstimate`]), checked before the forward pass.
    pub max_output_bytes: u64,
}

impl ReconstructOptions {
    /// Options with defaults for everything but the three paths.
    pub fn new(images: impl Into<PathBuf>, checkpoint: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            images: images.into(),
            checkpoint: checkpoint.into(),
            architecture: None,
            cameras: None,
            frames: None,
            times: TimeRequest::Inputs,
            width: None,
            chunk_frames: 4,
            out: out.into(),
            progress: Visibility::Hidden,
            max_output_bytes: DEFAULT_MAX_OUTPUT_BYTES,
        }
    }
}

struct Stages {
    started: Instant,
    list: Vec<StageTime>,
}

impl Stages {
    fn done(&mut self, stage: &str) {
        let seconds = self.started.elapsed().as_secs_f64();
        tracing::info!("{stage}: {seconds:.2} s");
        self.list.push(StageTime { stage: stage.into(), seconds });
        self.started = Instant::now();
    }
}

/// Files written so far, relative to the output folder.
struct Written {
    root: PathBuf,
    files: Vec<String>,
}

impl Written {
    fn path(&mut self, relative: &str) -> PathBuf {
        self.files.push(relative.to_string());
        self.root.join(relative)
    }
}

/// Runs the whole reconstruction on `device`, on one of rayon's threads so that the host kernels' parallel
/// operations keep a share of their work on the calling thread ([`on_pool_worker`]).
pub fn reconstruct(options: &ReconstructOptions, device: &Device) -> Result<Summary, ReconstructError> {
    on_pool_worker(|| reconstruct_here(options, device))
}

/// [`reconstruct`] on the calling thread.
fn reconstruct_here(options: &ReconstructOptions, device: &Device) -> Result<Summary, ReconstructError> {
    let mut stages = Stages { started: Instant::now(), list: Vec::new() };
    let inputs = InputSet::open(&options.images, options.frames.clone(), options.cameras.clone())?;
    let times_s = requested_times(&inputs, &options.times)?;
    let network = load_network(&options.checkpoint, options.architecture.as_ref(), device)?;
    let mut warnings = network.warnings.clone();
    for warning in &warnings {
        tracing::warn!("{warning}");
    }
    stages.done("load checkpoint");

    let preprocess = network.input_preprocess(options.width);
    let network_size = preprocess.plan(inputs.size)?.output;
    OutputEstimate::new(inputs.views.len(), inputs.cameras.len(), times_s.len(), network_size)
        .check(options.max_output_bytes)
        .map_err(ReconstructError::OutputTooLarge)?;
    let (images, size) = inputs.load(&preprocess)?;
    tracing::info!(
        "{} views ({} frames x {} cameras) at {} -> {size}; {} times to render",
        inputs.views.len(),
        inputs.frames.len(),
        inputs.cameras.len(),
        inputs.size,
        times_s.len()
    );
    stages.done("load images");

    let batch = images_tensor(&images, size, device);
    let prediction = forward_chunked(&network.model, batch.clone(), options.chunk_frames, MotionPath::WhereDynamic)?;
    let timeline = Timeline::new(&inputs.frames)?;
    let slots: Vec<ViewSlot> = inputs
        .views
        .iter()
        .map(|v| ViewSlot { rig_camera: v.camera, time: timeline.time(inputs.frame_at(v.time_s)) })
        .collect();
    let views = input_views(&prediction, &slots, InputCameras::Predicted, size)?;
    let cameras: Vec<PosedCamera> = views.iter().map(|v| v.camera).collect();
    stages.done("forward");

    std::fs::create_dir_all(&options.out).map_err(|e| ReconstructError::input(&options.out, e.to_string()))?;
    let mut written = Written { root: options.out.clone(), files: Vec::new() };
    write_cameras(&mut written, &inputs, &images, &cameras, size)?;
    let depth = host(prediction.depth.clone(), "depth")?;
    let dynamic = match prediction.dynamic_logit.clone() {
        Some(logit) => Some(host(burn::tensor::activation::sigmoid(logit), "dynamic probability")?),
        None => None,
    };
    write_maps(&mut written, &inputs, size, &depth, dynamic.as_deref())?;
    if dynamic.is_none() {
        warnings.push("the network has no instance head: no dynamic maps; everything is static".into());
    }
    stages.done("write cameras and maps");

    let scene_options = SceneOptions { assembly: network.assembly, ..SceneOptions::default() };
    let scene = prediction.scene(&network.model, &batch, views, &timeline, &scene_options)?;
    drop(prediction);
    let (counts, renders, input_psnr_db, instances) = match scene {
        None => {
            warnings.push("the network has no Gaussian head: no Gaussians, sky masks or renders".into());
            (GaussianCounts::default(), Vec::new(), Vec::new(), Vec::new())
        }
        Some(scene) => {
            let scene = with_instances(scene, &network.assembly)?;
            let frame_at = |time: f64| nearest_frame(&inputs.frames, &timeline, time);
            let instances = scene.pixels.instances().map_or_else(Vec::new, |found| instance_records(found, frame_at));
            stages.done("gaussians");
            let request = RenderRequest { inputs: &inputs, images: &images, times_s: &times_s, timeline, size };
            let counts = write_gaussians(&mut written, &scene, &request, &mut warnings)?;
            save_scene(&scene, &written.path(SCENE_FILE))?;
            stages.done("write gaussians");
            let (renders, input_psnr_db) = render_views(&mut written, &scene, &request, options.progress)?;
            stages.done("render");
            (counts, renders, input_psnr_db, instances)
        }
    };

    let pose_error = inputs.ground_truth.as_ref().and_then(|truth| {
        let reference = truth.world_from_camera[0];
        let truth: Vec<WorldFromCamera> = truth.world_from_camera.iter().map(|p| p.relative_to(&reference)).collect();
        let predicted: Vec<WorldFromCamera> = cameras.iter().map(|c| c.world_from_camera).collect();
        pose_error(&predicted, &truth)
    });
    written.files.push("summary.json".into());
    let summary = Summary {
        input: inputs.root.clone(),
        input_kind: inputs.kind.clone(),
        frames: inputs.frames.len(),
        cameras: inputs.cameras.clone(),
        views: inputs.views.len(),
        input_size: [inputs.size.width, inputs.size.height],
        network_size: [size.width, size.height],
        checkpoint: network.info,
        device: format!("{device:?}"),
        gaussians: counts,
        times_s,
        renders,
        input_psnr_db,
        pose_error,
        instances,
        stages: stages.list,
        peak_memory_mib: peak_memory_mib(),
        warnings,
        files: written.files,
    };
    let path = options.out.join("summary.json");
    let text = serde_json::to_string_pretty(&summary).expect("summaries serialise");
    std::fs::write(&path, text).map_err(|e| ReconstructError::input(&path, e.to_string()))?;
    Ok(summary)
}

/// `scene` with its moving objects found (for the summary, and for editing), when it has a dynamic head and
/// its assembly has not found them already.
fn with_instances(scene: Scene4d, assembly: &AssemblySettings) -> Result<Scene4d, ReconstructError> {
    if scene.pixels.dynamic_logit.is_none() || scene.pixels.instances().is_some() {
        return Ok(scene);
    }
    Ok(Scene4d { pixels: scene.pixels.with_instances(&assembly.instances)?, ..scene })
}

/// The input frame among `frames` whose scene time is nearest `time` (exactly it for an input's time).
fn nearest_frame(frames: &[usize], timeline: &Timeline, time: f64) -> usize {
    let distance = |frame: &&usize| (timeline.time(**frame as f64) - time).abs();
    *frames.iter().min_by(|a, b| distance(a).total_cmp(&distance(b))).expect("a reconstruction has input frames")
}

/// The summary's records of `instances`, `frame_at` naming the input frame of a scene time.
fn instance_records(instances: &Instances, frame_at: impl Fn(f64) -> usize) -> Vec<InstanceRecord> {
    instances
        .instances
        .iter()
        .map(|instance| InstanceRecord {
            id: instance.id,
            appearances: instance
                .appearances
                .iter()
                .map(|appearance| {
                    let pose = instance.trajectory.pose(appearance.time);
                    let r = pose.rotation;
                    InstanceAppearance {
                        scene_time: appearance.time,
                        frame: frame_at(appearance.time),
                        views: appearance.views.clone(),
                        pixels: appearance.pixels,
                        box_min: appearance.bounds[0].to_array(),
                        box_max: appearance.bounds[1].to_array(),
                        centre: appearance.centre.to_array(),
                        rotation_wxyz: [r.w, r.x, r.y, r.z],
                        translation: pose.translation.to_array(),
                    }
                })
                .collect(),
            residuals: instance.residuals.clone(),
        })
        .collect()
}

/// What the Gaussians are exported and the views rendered for.
struct RenderRequest<'a> {
    inputs: &'a InputSet,
    /// The inputs as the network saw them.
    images: &'a [PlanarImage],
    times_s: &'a [f64],
    timeline: Timeline,
    size: ImageSize,
}

impl RenderRequest<'_> {
    /// The scene time of `time_s` seconds since the first chosen frame.
    fn scene_time(&self, time_s: f64) -> f64 {
        self.timeline.time(self.inputs.frame_at(time_s))
    }
}

/// Writes the static, sky and per-time dynamic Gaussians as PLY; returns their counts.
fn write_gaussians(
    written: &mut Written,
    scene: &Scene4d,
    request: &RenderRequest<'_>,
    warnings: &mut Vec<String>,
) -> Result<GaussianCounts, ReconstructError> {
    let mut counts = GaussianCounts::default();
    let host_pixels = HostPixels::new(&scene.pixels)?;
    counts.per_pixel = host_pixels.len();
    let statics = host_pixels.static_cloud();
    counts.static_kept = statics.len();
    write_checked_ply(&written.path("gaussians/static.ply"), &statics)?;
    drop(statics);
    let sky_cloud = scene.sky.as_ref().map(sky_cloud).transpose()?.unwrap_or_default();
    counts.sky_kept = sky_cloud.len();
    write_checked_ply(&written.path("gaussians/sky.ply"), &sky_cloud)?;
    if scene.sky.is_none() {
        warnings.push("the network has no sky model: sky.ply is empty and renders have a black sky".into());
    }
    for (k, &time_s) in request.times_s.iter().enumerate() {
        let cloud = host_pixels.dynamic_cloud(scene.views(), request.inputs.cameras.len(), request.scene_time(time_s));
        counts.dynamic_kept.push(cloud.len());
        write_checked_ply(&written.path(&format!("gaussians/dynamic_t{k:04}.ply")), &cloud)?;
    }
    Ok(counts)
}

/// Writes `cloud` as PLY to `path` once every value of it is checked finite.
fn write_checked_ply(path: &Path, cloud: &GaussianCloud) -> Result<(), ReconstructError> {
    finite::check_cloud(path, cloud)?;
    Ok(write_ply(path, cloud)?)
}

/// Writes the render `rgb` as PNG to `path` once every value of it is checked finite.
fn write_checked_render(path: &Path, size: ImageSize, rgb: &[f32]) -> Result<(), ReconstructError> {
    finite::check_f32(path, "rendered colours", rgb)?;
    Ok(write_rgb_png(path, size, rgb)?)
}

/// Re-renders the input views (sky masks, PSNR) and renders every camera at every requested time; returns the
/// render records and the input views' PSNR.
fn render_views(
    written: &mut Written,
    scene: &Scene4d,
    request: &RenderRequest<'_>,
    progress: Visibility,
) -> Result<(Vec<RenderRecord>, Vec<f64>), ReconstructError> {
    let (inputs, size) = (request.inputs, request.size);
    let views = scene.views();
    let total = inputs.views.len() + request.times_s.len() * inputs.cameras.len();
    let bar = styled_bar("rendering {bar:30} {pos}/{len} [{elapsed}<{eta}]", progress, Some(total as u64));
    // Input views re-rendered: the sky masks, the PSNR, and the renders at input times.
    let mut at_inputs: HashMap<(usize, u64), (Vec<f32>, AssemblyCounts)> = HashMap::new();
    let mut input_psnr_db = Vec::new();
    for (i, view) in inputs.views.iter().enumerate() {
        let target = TargetView { rig_camera: view.camera, time: views[i].time, camera: views[i].camera };
        let render = scene.render(&target)?;
        let rgb = host(render.rgb, "render")?;
        let alpha = host(render.alpha, "render alpha")?;
        let sky_file = written.path(&format!("sky/{}.png", view.name));
        finite::check_f32(&sky_file, "rendered opacities (the sky mask's source)", &alpha)?;
        let sky_mask: Vec<bool> = alpha.iter().map(|&a| a < 0.5).collect();
        write_binary_png(&sky_file, size, &sky_mask)?;
        input_psnr_db.push(psnr(&rgb, &request.images[i].interleaved()));
        at_inputs.insert((view.camera, view.time_s.to_bits()), (rgb, render.counts));
        bar.inc(1);
    }
    let input_times = inputs.input_times();
    let mut renders = Vec::new();
    for (k, &time_s) in request.times_s.iter().enumerate() {
        for camera in 0..inputs.cameras.len() {
            let file = format!("renders/t{k:04}_cam{camera}.png");
            let (rgb, assembly) = match at_inputs.get(&(camera, time_s.to_bits())) {
                Some((rgb, assembly)) => (rgb.clone(), *assembly),
                None => {
                    let time = request.scene_time(time_s);
                    let target = TargetView { rig_camera: camera, time, camera: scene.camera_at(camera, time)? };
                    let render = scene.render(&target)?;
                    (host(render.rgb, "render")?, render.counts)
                }
            };
            write_checked_render(&written.path(&file), size, &rgb)?;
            let nearest = nearest_in_time(inputs.views.iter().map(|v| (v.camera, v.time_s)), camera, time_s)
                .map(|position| &inputs.views[position])
                .ok_or(ReconstructError::NoInputView { camera })?;
            renders.push(RenderRecord {
                file,
                camera,
                time_s,
                at_input: input_times.contains(&time_s),
                nearest_input: input_image_file(&nearest.name),
                candidates: assembly.candidates,
                transparent: assembly.transparent,
                off_screen: assembly.off_screen,
                static_kept: assembly.static_kept,
                dynamic_kept: assembly.dynamic_kept,
            });
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok((renders, input_psnr_db))
}

/// Where the input view `name` is written (as the network saw it).
fn input_image_file(name: &str) -> String {
    format!("images/{name}.png")
}

/// The requested times in seconds, ascending as given; each within the input frames' times.
fn requested_times(inputs: &InputSet, request: &TimeRequest) -> Result<Vec<f64>, ReconstructError> {
    let input_times = inputs.input_times();
    match request {
        TimeRequest::Inputs => Ok(input_times),
        TimeRequest::Seconds(times) => {
            check_times(times, &input_times)?;
            Ok(times.clone())
        }
        TimeRequest::Every(k) => {
            check_every(*k)?;
            let mut times = Vec::new();
            for pair in input_times.windows(2) {
                times.extend((0..*k).map(|i| pair[0] + (pair[1] - pair[0]) * i as f64 / *k as f64));
            }
            times.extend(input_times.last());
            Ok(times)
        }
    }
}

fn images_tensor(images: &[PlanarImage], size: ImageSize, device: &Device) -> Tensor<5> {
    let data: Vec<f32> = images.iter().flat_map(|i| i.data.iter().copied()).collect();
    let shape = [1, images.len(), 3, size.height as usize, size.width as usize];
    Tensor::from_data(TensorData::new(data, shape), device)
}

fn host<const D: usize>(tensor: Tensor<D>, name: &str) -> Result<Vec<f32>, ReconstructError> {
    Ok(host_f32(tensor, name)?)
}

/// `[x, y, z]` rows of an `[N, 3]` tensor.
fn triples(tensor: &Tensor<2>, name: &str) -> Result<Vec<[f32; 3]>, ReconstructError> {
    Ok(host(tensor.clone(), name)?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// `[w, x, y, z]` rows of an `[N, 4]` tensor.
fn quads(tensor: &Tensor<2>, name: &str) -> Result<Vec<[f32; 4]>, ReconstructError> {
    Ok(host(tensor.clone(), name)?.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
}

/// PSNR in dB of two images in `[0, 1]` (the render clamped as it is saved).
fn psnr(rendered: &[f32], reference: &[f32]) -> f64 {
    let mse = rendered.iter().zip(reference).map(|(a, b)| ((a.clamp(0.0, 1.0) - b) as f64).powi(2)).sum::<f64>()
        / reference.len().max(1) as f64;
    10.0 * (1.0 / mse.max(1e-12)).log10()
}

fn write_cameras(
    written: &mut Written,
    inputs: &InputSet,
    images: &[PlanarImage],
    cameras: &[PosedCamera],
    size: ImageSize,
) -> Result<(), ReconstructError> {
    let mut records = Vec::new();
    let (mut colmap_cameras, mut colmap_images, mut frames) = (Vec::new(), Vec::new(), Vec::new());
    for (i, ((view, image), camera)) in inputs.views.iter().zip(images).zip(cameras).enumerate() {
        let file = input_image_file(&view.name);
        write_rgb_png(&written.path(&file), size, &image.interleaved())?;
        records.push(CameraRecord {
            name: view.name.clone(),
            frame: view.frame,
            camera: view.camera,
            time_s: view.time_s,
            size,
            intrinsics: camera.intrinsics,
            world_from_camera: camera.world_from_camera,
        });
        let id = i as u32 + 1;
        colmap_cameras.push(ColmapCamera { id, size, intrinsics: camera.intrinsics });
        colmap_images.push(ColmapImage {
            id,
            camera_id: id,
            name: format!("{}.png", view.name),
            camera_from_world: camera.world_from_camera.inverse(),
        });
        frames.push(NerfstudioFrame {
            file_path: file,
            size,
            intrinsics: camera.intrinsics,
            world_from_camera: camera.world_from_camera,
        });
    }
    let world = "the camera frame of the first input view (predicted poses; distances up to scale)";
    finite::check_cameras(&written.root.join("cameras.json"), cameras)?;
    write_cameras_json(&written.path("cameras.json"), &Convention::opencv(world), &records)?;
    for file in ["sparse/0/cameras.txt", "sparse/0/images.txt", "sparse/0/points3D.txt"] {
        written.path(file);
    }
    write_colmap(&written.root.join("sparse/0"), &colmap_cameras, &colmap_images)?;
    write_transforms(&written.path("transforms.json"), &frames)?;
    Ok(())
}

fn write_maps(
    written: &mut Written,
    inputs: &InputSet,
    size: ImageSize,
    depth: &[f32],
    dynamic: Option<&[f32]>,
) -> Result<(), ReconstructError> {
    let per_view = size.area();
    let max = depth.iter().copied().filter(|d| d.is_finite()).fold(0.0f32, f32::max);
    let scale = scale_for(max);
    for (i, view) in inputs.views.iter().enumerate() {
        let range = i * per_view..(i + 1) * per_view;
        finite::check_f32(&written.root.join(format!("depth/{}.npy", view.name)), "depth", &depth[range.clone()])?;
        if let Some(dynamic) = dynamic {
            let file = written.root.join(format!("dynamic/{}.png", view.name));
            finite::check_f32(&file, "dynamic probabilities", &dynamic[range.clone()])?;
        }
        write_depth_npy(&written.path(&format!("depth/{}.npy", view.name)), size, &depth[range.clone()])?;
        write_depth_png16(&written.path(&format!("depth/{}.png", view.name)), size, &depth[range.clone()], scale)?;
        written.path(&format!("depth/{}.json", view.name));
        if let Some(dynamic) = dynamic {
            write_probability_png(&written.path(&format!("dynamic/{}.png", view.name)), size, &dynamic[range])?;
        }
    }
    Ok(())
}

/// The per-pixel Gaussians on the host, activated.
struct HostPixels {
    cloud: GaussianCloud,
    /// Opacity before the static/dynamic split.
    opacity: Vec<f32>,
    /// `sigmoid(dynamic logit)`; zeros without an instance head.
    dynamic_probability: Vec<f32>,
    /// World displacement per unit of scene time, with a motion head.
    velocity: Option<Vec<[f32; 3]>>,
    per_view: usize,
}

impl HostPixels {
    fn new(pixels: &PixelGaussians) -> Result<Self, ReconstructError> {
        let opacity = host(pixels.opacity.clone(), "opacity")?;
        let dynamic_probability = match &pixels.dynamic_logit {
            Some(logit) => host(burn::tensor::activation::sigmoid(logit.clone()), "dynamic probability")?,
            None => vec![0.0; opacity.len()],
        };
        let cloud = GaussianCloud {
            means: triples(&pixels.means, "means")?,
            quats_wxyz: quads(&pixels.quats_wxyz, "rotations")?,
            scales: triples(&pixels.scales, "scales")?,
            opacities: Vec::new(),
            colors: triples(&pixels.colors, "colours")?,
        };
        let velocity = match &pixels.velocity {
            Some(velocity) => Some(triples(velocity, "velocity")?),
            None => None,
        };
        Ok(Self { cloud, opacity, dynamic_probability, velocity, per_view: pixels.per_view() })
    }

    fn len(&self) -> usize {
        self.opacity.len()
    }

    /// Gaussians from `range` with opacity `opacity(i)`, kept at or above the rasteriser's threshold, moved
    /// by their velocity over `elapsed` scene time (when there is one).
    fn select(&self, range: Range<usize>, opacity: impl Fn(usize) -> f32, elapsed: f32, into: &mut GaussianCloud) {
        for i in range {
            let o = opacity(i);
            if o >= MIN_OPACITY {
                let mean = self.cloud.means[i];
                into.means.push(match &self.velocity {
                    Some(velocity) => std::array::from_fn(|k| mean[k] + velocity[i][k] * elapsed),
                    None => mean,
                });
                into.quats_wxyz.push(self.cloud.quats_wxyz[i]);
                into.scales.push(self.cloud.scales[i]);
                into.colors.push(self.cloud.colors[i]);
                into.opacities.push(o);
            }
        }
    }

    /// Every pixel's static part, opacity `o (1 - p_dynamic)`, unfaded.
    fn static_cloud(&self) -> GaussianCloud {
        let mut cloud = GaussianCloud::default();
        self.select(0..self.len(), |i| self.opacity[i] * (1.0 - self.dynamic_probability[i]), 0.0, &mut cloud);
        cloud
    }

    /// The dynamic part shown at scene time `time`: each camera's nearest input view, opacity `o p_dynamic`,
    /// moved to `time` with a motion head.
    fn dynamic_cloud(&self, views: &[InputView], cameras: usize, time: f64) -> GaussianCloud {
        let mut cloud = GaussianCloud::default();
        for camera in 0..cameras {
            if let Some(view) = nearest_view(views, camera, time) {
                let range = view * self.per_view..(view + 1) * self.per_view;
                let elapsed = (time - views[view].time) as f32;
                self.select(range, |i| self.opacity[i] * self.dynamic_probability[i], elapsed, &mut cloud);
            }
        }
        cloud
    }
}

fn sky_cloud(sky: &dggt_model::sky::SkyGaussians) -> Result<GaussianCloud, ReconstructError> {
    Ok(GaussianCloud {
        means: triples(&sky.means, "sky means")?,
        quats_wxyz: quads(&sky.quats, "sky rotations")?,
        scales: triples(&sky.scales, "sky scales")?,
        opacities: host(sky.opacities.clone(), "sky opacities")?,
        colors: triples(&sky.colors, "sky colours")?,
    })
}
