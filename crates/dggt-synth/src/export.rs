//! Writing a scene in the scene-export layout ([`dggt_data::ExportLayout`]), frames `0..F`, cameras `0..C`, in
//! any [`ExportVariant`]. The variant decides the camera and pose files, the dynamic-mask folders and the lidar
//! rows; everything else is written alike, so one scene read through every variant gives the same cameras.
//!
//! | path | content |
//! |---|---|
//! | `images/{t:03}_{cam}.jpg` | colour, JPEG quality 92, 2x2 supersampled |
//! | `intrinsics/{cam}.txt` | `fx fy cx cy 0 0 0 0 0`, one per line (no distortion; image spans `[0,W]x[0,H]`) |
//! | `extrinsics/{cam}.txt` | Waymo variants: 4x4 camera -> ego in Waymo camera axes (x forward, y left, z up); readers get the OpenCV mounting as `extrinsic · M` ([`dggt_geom::axes`]). Argoverse 2: camera -> ego in OpenCV axes |
//! | `extrinsics/{t:03}_{cam}.txt` | nuScenes: 4x4 camera -> world in OpenCV axes, per frame |
//! | `ego_pose/{t:03}.txt` | all but nuScenes: 4x4 ego -> world; frame 0 is the identity (the world is the first ego frame: x along the road, z up) |
//! | `lidar_pose/{t:03}.txt` | nuScenes: 4x4 lidar -> world, the lidar's axes being the ego's turned a quarter right (x right, y forward, z up) |
//! | `lidar/{t:03}.bin` | with [`Sweeps::Write`]: the sweep of [`crate::lidar`] in the variant's rows ([`dggt_data::lidar::LidarFormat`]): ego frame, or the lidar frame for nuScenes |
//! | `timestamps.txt` | `frame seconds` per line (10 Hz) |
//! | `sky_masks/{t:03}_{cam}.png` | 255 where the pixel-centre ray hits nothing |
//! | `dynamic_masks/all/…png`, `dynamic_masks/vehicle/…png` | 255 where the pixel-centre ray crosses the 3D box of a car moving faster than 1 m/s, ignoring occlusion (the projected-box mask); every mover is a vehicle, so both are equal. The STORM variant writes this mask once, flat, as `dynamic_masks/{t:03}_{cam}.png` |
//! | `dynamic_masks/human/…png` | all 0 (no pedestrians) |
//! | `fine_dynamic_masks/all/…png` | 255 where the pixel-centre ray actually hits such a car (exact, occlusion-aware) |
//! | `depth_flows_4/{t:03}_{cam}.npy` | float32 `(H/4, W/4, 4)` (integer division): the ray through full-resolution coordinates `(4 col + 2, 4 row + 2)`; channel 0 its z-depth (m, along the optical axis, 0 for sky), channels 1-3 the world-frame velocity (m/s) of the surface point hit (zero for static surfaces and sky), including the rotation of turning cars |
//! | `instances/instances_info.json` | every car, see below |
//! | `instances/frame_instances.json` | `{"<frame>": [instance ids present], ...}` for every frame |
//! | `synth.json` | the configuration, the variant (`layout`), the command line that reproduces the scene (edits included), these conventions in brief, and for an edited scene (`--remove-object`, `--move-object`) its `edits`: the exact [`ObjectEdit`](crate::ObjectEdit) of each edited object and their convention |
//!
//! `instances_info.json` maps each instance id (a string; ids are `0..N`, moving cars first) to
//! `{"id", "class_name": "vehicle", "dynamic", "box_size": [length, width, height], "frame_annotations":
//! {"frame_idx": [...], "obj_to_world": [4x4 row-major, ...], "box_size": [[l, w, h], ...]}}`. `obj_to_world` maps
//! box coordinates (origin at the box centre, x forward, y left, z up) to the world of `ego_pose`. An instance is
//! *present* in a frame, and annotated there, when a pixel-centre ray of some camera hits it or, for moving cars,
//! crosses its box; so every dynamic-mask pixel belongs to an instance annotated in that frame. Objects are listed
//! in id order and frames in time order; objects removed by an edit are not listed, and their ids are not reused.
//! Every file is written atomically; files already in the folder that this export does not produce are left alone.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use dggt_data::instances::{FrameAnnotations, OrderedMap};
use dggt_data::layout::SYNTH_DESCRIPTION;
use dggt_data::lidar::write_lidar;
use dggt_data::variant::{CameraAxes, CameraMounting, DynamicMaskFolders, FramePoses, nuscenes_lidar_from_ego};
use dggt_data::{DynamicMaskKind, ExportLayout, ExportVariant, images, io, npy, text};
use image::GrayImage;
use rayon::prelude::*;
use serde::Serialize;

use crate::change::{ObjectEdit, Presence};
use crate::config::{FRAME_INTERVAL_S, SynthConfig};
use crate::error::{Result, SynthError};
use crate::generate::generate;
use crate::object_id::ObjectId;
use crate::rig::HORIZONTAL_FOV_DEG;
use crate::scene::SynthScene;

/// JPEG quality of the colour images.
pub const JPEG_QUALITY: u8 = 92;

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SynthSummary {
    pub root: PathBuf,
    pub frames: usize,
    pub cameras: usize,
    /// Colour images written (`frames * cameras`).
    pub images: usize,
    /// Cars listed in `instances_info.json`.
    pub instances: usize,
    pub moving_instances: usize,
    /// Pixels set in all fine dynamic masks together.
    pub dynamic_pixels: u64,
    /// Pixels set in all sky masks together.
    pub sky_pixels: u64,
    /// Objects an edit removed, in id order.
    pub removed_objects: Vec<ObjectId>,
    /// Objects an edit moved, in id order.
    pub moved_objects: Vec<ObjectId>,
}

/// Whether an export gets the lidar sweeps of [`crate::lidar`] (`lidar/{t}.bin`, about 0.6 MB a frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweeps {
    Write,
    Skip,
}

/// A lidar sweep's bytes at most (a sweep is about 0.6 MB).
const SWEEP_BYTES_AT_MOST: u64 = 1_000_000;
/// Bytes per pixel of a view's files at most: the image (RGB before compression), the sky, dynamic and fine
/// dynamic masks, and the quarter-resolution depth and flow (16 bytes a sample, one sample per 16 pixels).
const VIEW_BYTES_PER_PIXEL: u64 = 3 + 3 + 1;

/// The most the export of `config` can take on disk, in bytes: what a caller checks against its bound before
/// writing anything.
pub fn largest_output_bytes(config: &SynthConfig, sweeps: Sweeps) -> u64 {
    let pixels = config.width as u64 * config.height as u64;
    let views = config.frames as u64 * config.cameras as u64;
    let lidar = match sweeps {
        Sweeps::Write => config.frames as u64 * SWEEP_BYTES_AT_MOST,
        Sweeps::Skip => 0,
    };
    views.saturating_mul(pixels * VIEW_BYTES_PER_PIXEL).saturating_add(lidar)
}

/// Generates the scene of `config` and writes it to `out_dir` in `variant`.
pub fn synthesize(
    config: &SynthConfig,
    out_dir: &Path,
    variant: ExportVariant,
    sweeps: Sweeps,
) -> Result<SynthSummary> {
    let scene = generate(config)?;
    write_export(&scene, out_dir, variant, sweeps)
}

#[derive(Serialize)]
struct InstanceInfo {
    id: ObjectId,
    class_name: &'static str,
    dynamic: bool,
    box_size: [f64; 3],
    frame_annotations: FrameAnnotations,
}

#[derive(Serialize)]
struct Conventions {
    world: &'static str,
    pixels: &'static str,
    extrinsics: &'static str,
    dynamic_masks: &'static str,
    fine_dynamic_masks: &'static str,
    depth_flows_4: &'static str,
    instances: &'static str,
}

#[derive(Serialize)]
struct Description<'a> {
    generator: &'static str,
    layout: ExportVariant,
    description: &'static str,
    command: String,
    config: &'a SynthConfig,
    frame_interval_s: f64,
    camera_names: Vec<String>,
    horizontal_fov_deg: f64,
    moving_instances: Vec<ObjectId>,
    parked_instances: Vec<ObjectId>,
    conventions: Conventions,
    #[serde(skip_serializing_if = "Option::is_none")]
    edits: Option<Edits>,
}

/// The edits of an edited scene, as `synth.json` records them.
#[derive(Serialize)]
struct Edits {
    convention: &'static str,
    objects: Vec<ObjectEdit>,
}

const EDIT_CONVENTION: &str = "applied after each object's placement at every time; remove: the object is drawn \
                               nowhere; move: x' = Rz(yaw) (x - pivot) + pivot + offset, world axes, offset and \
                               pivot in m, yaw in radians counter-clockwise seen from above (about +z)";

const CONVENTIONS: Conventions = Conventions {
    world: "metric, z up, x along the road; the first ego pose is the identity",
    pixels: "image spans [0,W]x[0,H]; pixel (col,row) centre at (col+0.5,row+0.5); ray ((u-cx)/fx,(v-cy)/fy,1) in OpenCV camera axes",
    extrinsics: "camera -> ego in Waymo camera axes (x forward, y left, z up)",
    dynamic_masks: "projected 3D boxes of cars faster than 1 m/s (pixel-centre ray crosses the box, occlusion ignored)",
    fine_dynamic_masks: "exact: the pixel-centre ray hits a car faster than 1 m/s",
    depth_flows_4: "(H/4,W/4,4) float32 at full-resolution coordinates (4col+2,4row+2): z-depth in m (0 = sky), then world velocity in m/s",
    instances: "obj_to_world: box centre origin, x forward, y left, z up; box_size [length,width,height]",
};

fn json_bytes(what: &'static str, value: &impl Serialize) -> Result<Vec<u8>> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|source| SynthError::Json { what, source })?;
    bytes.push(b'\n');
    Ok(bytes)
}

/// What one rendered view contributes to the scene-wide files.
struct ViewRecord {
    frame: usize,
    present: BTreeSet<ObjectId>,
    dynamic_pixels: u64,
    sky_pixels: u64,
}

fn count_set(mask: &GrayImage) -> u64 {
    mask.pixels().filter(|p| p.0[0] != 0).count() as u64
}

fn write_view(
    scene: &SynthScene,
    layout: &ExportLayout,
    variant: ExportVariant,
    frame: usize,
    camera: usize,
) -> Result<ViewRecord> {
    let view = scene.render_view(frame, camera)?;
    images::write_jpeg(&layout.image(frame, camera), &view.image, JPEG_QUALITY)?;
    images::write_png_gray(&layout.sky_mask(frame, camera), &view.sky_mask)?;
    match variant.dynamic_masks() {
        DynamicMaskFolders::PerClass => {
            for kind in [DynamicMaskKind::All, DynamicMaskKind::Vehicle] {
                images::write_png_gray(&layout.dynamic_mask(kind, frame, camera), &view.dynamic_box_mask)?;
            }
            let nobody = GrayImage::new(view.image.width(), view.image.height());
            images::write_png_gray(&layout.dynamic_mask(DynamicMaskKind::Human, frame, camera), &nobody)?;
        }
        DynamicMaskFolders::Flat => {
            images::write_png_gray(&layout.flat_dynamic_mask(frame, camera), &view.dynamic_box_mask)?;
        }
    }
    images::write_png_gray(&layout.dynamic_mask(DynamicMaskKind::FineAll, frame, camera), &view.dynamic_mask)?;
    npy::write_npy_f32(&layout.depth_flow(frame, camera), &view.depth_flow_shape, &view.depth_flow)?;
    Ok(ViewRecord {
        frame,
        present: view.visible_instances,
        dynamic_pixels: count_set(&view.dynamic_mask),
        sky_pixels: count_set(&view.sky_mask),
    })
}

/// The cameras' calibration and the frames' poses, in the variant's files.
fn write_geometry(scene: &SynthScene, layout: &ExportLayout, variant: ExportVariant) -> Result<()> {
    let k = scene.intrinsics();
    let intrinsic_rows = [k.fx, k.fy, k.cx, k.cy, 0.0, 0.0, 0.0, 0.0, 0.0].map(|v| [v]);
    for camera in scene.rig() {
        text::write_rows(&layout.intrinsics(camera.id), &intrinsic_rows)?;
        match (variant.camera_mounting(), variant.camera_axes()) {
            (CameraMounting::FixedOnEgo, CameraAxes::Waymo) => {
                text::write_rows(&layout.extrinsics(camera.id), &camera.extrinsic_rows)?;
            }
            (CameraMounting::FixedOnEgo, CameraAxes::OpenCv) => {
                text::write_rows(&layout.extrinsics(camera.id), &camera.ego_from_camera.to_rows())?;
            }
            (CameraMounting::PerFrameInWorld, _) => {
                for frame in 0..scene.config().frames {
                    let pose = scene.world_from_camera(frame, camera.id).expect("frame and camera of the scene");
                    text::write_rows(&layout.extrinsics_at(frame, camera.id), &pose.to_rows())?;
                }
            }
        }
    }
    for (frame, rows) in scene.ego_pose_rows.iter().enumerate() {
        match variant.frame_poses() {
            FramePoses::Ego => text::write_rows(&layout.ego_pose(frame), rows)?,
            FramePoses::Lidar => {
                let world_from_lidar = scene.world_from_ego[frame] * nuscenes_lidar_from_ego().inverse();
                text::write_rows(&layout.lidar_pose(frame), &world_from_lidar.to_rows())?;
            }
        }
    }
    let times: Vec<[f64; 2]> =
        (0..scene.config().frames).map(|frame| [frame as f64, SynthConfig::frame_time(frame)]).collect();
    Ok(text::write_rows(&layout.timestamps(), &times)?)
}

/// The lidar sweep of every frame, in the variant's rows and frame.
fn write_sweeps(scene: &SynthScene, layout: &ExportLayout, variant: ExportVariant) -> Result<()> {
    (0..scene.config().frames).into_par_iter().try_for_each(|frame| {
        let mut points = crate::lidar::sweep(scene, frame)?;
        if variant.frame_poses() == FramePoses::Lidar {
            let lidar_from_ego = nuscenes_lidar_from_ego();
            for p in &mut points {
                p.origin = lidar_from_ego.transform_point(p.origin);
                p.point = lidar_from_ego.transform_point(p.point);
                p.flow = lidar_from_ego.transform_vector(p.flow);
            }
        }
        Ok(write_lidar(&layout.lidar(frame), variant.lidar_format(), &points)?)
    })
}

/// The ids of the objects whose presence passes `select`.
fn edited_objects(scene: &SynthScene, select: impl Fn(Presence) -> bool) -> Vec<ObjectId> {
    scene.objects().iter().filter(|o| select(o.presence())).map(|o| o.id()).collect()
}

/// Renders every view of `scene` and writes the whole export to `out_dir` (created if needed) in `variant`.
pub fn write_export(
    scene: &SynthScene,
    out_dir: &Path,
    variant: ExportVariant,
    sweeps: Sweeps,
) -> Result<SynthSummary> {
    let config = scene.config();
    let layout = ExportLayout::new(out_dir);
    let views: Vec<(usize, usize)> =
        (0..config.frames).flat_map(|frame| (0..config.cameras).map(move |camera| (frame, camera))).collect();
    let records = views
        .par_iter()
        .map(|&(frame, camera)| write_view(scene, &layout, variant, frame, camera))
        .collect::<Result<Vec<_>>>()?;
    write_geometry(scene, &layout, variant)?;
    if sweeps == Sweeps::Write {
        write_sweeps(scene, &layout, variant)?;
    }

    let mut present: Vec<BTreeSet<ObjectId>> = vec![BTreeSet::new(); config.frames];
    for record in &records {
        present[record.frame].extend(record.present.iter().copied());
    }
    let instances: Vec<(String, InstanceInfo)> = scene
        .instances()
        .map(|object| {
            let frames: Vec<usize> = (0..config.frames).filter(|&f| present[f].contains(&object.id())).collect();
            let box_size = object.box_size();
            let info = InstanceInfo {
                id: object.id(),
                class_name: "vehicle",
                dynamic: object.motion().is_some(),
                box_size,
                frame_annotations: FrameAnnotations {
                    obj_to_world: frames
                        .iter()
                        .map(|&f| object.world_from_object(SynthConfig::frame_time(f)).to_rows())
                        .collect(),
                    box_size: vec![box_size; frames.len()],
                    frame_idx: frames,
                },
            };
            (object.id().to_string(), info)
        })
        .collect();
    let moving: Vec<ObjectId> = scene.instances().filter(|o| o.motion().is_some()).map(|o| o.id()).collect();
    let parked: Vec<ObjectId> = scene.instances().filter(|o| o.motion().is_none()).map(|o| o.id()).collect();
    let instance_count = instances.len();
    io::write_atomically(&layout.instances_info(), &json_bytes("instances_info.json", &OrderedMap(instances))?)?;
    let frame_instances: Vec<(String, Vec<ObjectId>)> =
        present.iter().enumerate().map(|(f, ids)| (f.to_string(), ids.iter().copied().collect())).collect();
    io::write_atomically(
        &layout.frame_instances(),
        &json_bytes("frame_instances.json", &OrderedMap(frame_instances))?,
    )?;

    let description = Description {
        generator: "dggt-synth",
        layout: variant,
        description: "Procedural driving street rendered by an analytic ray caster: road with lane markings, \
                      sidewalks, textured buildings, poles, trees, parked cars and moving cars (one turning into a \
                      side street), seen from a forward-driving ego vehicle at 10 Hz.",
        command: scene.command_line(),
        config,
        frame_interval_s: FRAME_INTERVAL_S,
        camera_names: (0..config.cameras).map(|id| variant.camera_name(id)).collect(),
        horizontal_fov_deg: HORIZONTAL_FOV_DEG,
        moving_instances: moving.clone(),
        parked_instances: parked,
        conventions: CONVENTIONS,
        edits: Some(scene.edits())
            .filter(|edits| !edits.is_empty())
            .map(|objects| Edits { convention: EDIT_CONVENTION, objects }),
    };
    io::write_atomically(&layout.synth_description(), &json_bytes(SYNTH_DESCRIPTION, &description)?)?;

    tracing::debug!(root = %out_dir.display(), views = records.len(), "synthetic scene written");
    Ok(SynthSummary {
        root: out_dir.to_owned(),
        frames: config.frames,
        cameras: config.cameras,
        images: records.len(),
        instances: instance_count,
        moving_instances: moving.len(),
        dynamic_pixels: records.iter().map(|r| r.dynamic_pixels).sum(),
        sky_pixels: records.iter().map(|r| r.sky_pixels).sum(),
        removed_objects: edited_objects(scene, |p| matches!(p, Presence::Removed)),
        moved_objects: edited_objects(scene, |p| matches!(p, Presence::Moved(_))),
    })
}
