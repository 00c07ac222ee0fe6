//! A 4D scene saved to one file and read back: what `dggt reconstruct` leaves beside its outputs so that the
//! scene can be rendered and edited later (`dggt edit`) without the network.
//!
//! The file is safetensors. Tensors, little-endian:
//! - `pixels.means` `[M, 3]`, `pixels.quats_wxyz` `[M, 4]`, `pixels.scales` `[M, 3]` (linear),
//!   `pixels.colors` `[M, K]` (`K` colour channels, 3 for RGB), `pixels.opacity`, `pixels.lifespan`, `pixels.source_time` `[M]` and, when the
//!   network predicts them, `pixels.dynamic_logit` `[M]` and `pixels.velocity` `[M, 3]` (world axes per unit of
//!   scene time), and with a learnt flow `pixels.flow_to_next` and `pixels.flow_to_previous` `[M, 3]` (world
//!   displacements to the neighbouring inputs, [`crate::LearntFlow`]): f32, one row per input pixel, view-major as
//!   [`PixelGaussians`] holds them;
//! - `instances.labels` `[S, H·W]` u32 (position in the instance list, `u32::MAX` for none), when found;
//! - `sky.means`, `sky.quats_wxyz`, `sky.scales`, `sky.colors` `[V, ..]`, `sky.opacities` `[V]`: f32, the sky's
//!   Gaussians as rendered (the colour field that made them is not kept), when the network has a sky model.
//!
//! Under the metadata key [`METADATA_KEY`], a JSON [`SceneRecord`]: the image size, every input view (rig
//! camera, scene time, world-from-camera pose as 3x4 rows in OpenCV axes, pinhole intrinsics in pixels), the
//! instances (appearances, trajectory keys, placement; quaternions `w x y z`) and the assembly choices that change
//! a render. Everything read back is checked: a file that does not hold a consistent scene is an error naming the
//! file and the tensor or field.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{ImageSize, PinholeIntrinsics, PosedCamera, WorldFromCamera};
use dggt_instances::{Appearance, Instance, Instances, KeyPose, Placement, RigidMotion, Trajectory};
use dggt_model::host::host_f32;
use dggt_model::sky::SkyGaussians;
use safetensors::{Dtype, SafeTensors};
use serde::{Deserialize, Serialize};

use crate::assemble::AssemblySettings;
use crate::error::SceneError;
use crate::motion::DynamicMotion;
use crate::pixels::PixelGaussians;
use crate::scene4d::Scene4d;
use crate::timeline::{DynamicBlend, InputView};

/// The metadata key of the scene's JSON record.
pub const METADATA_KEY: &str = "dggt.scene";
/// The file name `dggt reconstruct` gives a saved scene.
pub const SCENE_FILE: &str = "scene.safetensors";
/// The version of the record written; a reader refuses others.
const FORMAT_VERSION: u32 = 1;

/// Everything of a scene that is not a tensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneRecord {
    pub version: u32,
    /// `[width, height]` of every input view, pixels.
    pub size: [u32; 2],
    pub views: Vec<ViewRecord>,
    pub instances: Option<Vec<InstanceRecord>>,
    pub assembly: AssemblyRecord,
}

/// One input view: its rig camera, scene time and camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewRecord {
    pub rig_camera: usize,
    pub time: f64,
    /// World-from-camera, OpenCV axes (x right, y down, z forward), rows of `[R | t]`.
    pub world_from_camera: [[f64; 4]; 3],
    /// `[fx, fy, cx, cy]` in pixels of the saved size.
    pub intrinsics: [f64; 4],
}

/// The assembly choices that change a render.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssemblyRecord {
    pub dynamic_blend: DynamicBlend,
    pub dynamic_motion: DynamicMotion,
    pub eps2d: f32,
    pub near_plane: f32,
    pub far_plane: f32,
}

/// One moving object (see [`Instance`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceRecord {
    pub id: u32,
    pub appearances: Vec<AppearanceRecord>,
    pub reference_centre: [f64; 3],
    pub keys: Vec<KeyRecord>,
    pub residuals: Vec<f64>,
    pub placement: PlacementRecord,
}

/// An edit's change along the trajectory (see [`Placement`]): `turn` a unit quaternion `w x y z`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacementRecord {
    pub turn_wxyz: [f64; 4],
    pub offset: [f64; 3],
}

/// One object at one input time (see [`Appearance`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AppearanceRecord {
    pub time: f64,
    pub views: Vec<usize>,
    pub pixels: usize,
    pub box_min: [f64; 3],
    pub box_max: [f64; 3],
    pub centre: [f64; 3],
}

/// A trajectory key: the motion from the reference to `time`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyRecord {
    pub time: f64,
    pub from_reference: MotionRecord,
}

/// `x -> R x + t` in world axes, `R` as a unit quaternion `w x y z`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionRecord {
    pub rotation_wxyz: [f64; 4],
    pub translation: [f64; 3],
}

impl From<&RigidMotion> for MotionRecord {
    fn from(motion: &RigidMotion) -> Self {
        let r = motion.rotation;
        Self { rotation_wxyz: [r.w, r.x, r.y, r.z], translation: motion.translation.to_array() }
    }
}

impl MotionRecord {
    fn motion(&self) -> RigidMotion {
        let [w, x, y, z] = self.rotation_wxyz;
        RigidMotion { rotation: DQuat::from_xyzw(x, y, z, w), translation: DVec3::from_array(self.translation) }
    }
}

/// The saved scene `path` names: a reconstruction folder's [`SCENE_FILE`], or the file itself.
pub fn scene_file(path: &Path) -> PathBuf {
    if path.is_dir() { path.join(SCENE_FILE) } else { path.to_path_buf() }
}

/// Writes `scene` to `path` (see the module's doc), atomically: a reader never sees half a file. A scene with a
/// value that is not finite (a Gaussian's, or an instance's pose: JSON has no infinity) is refused, as reading it
/// back would be.
pub fn save_scene(scene: &Scene4d, path: &Path) -> Result<(), SceneError> {
    let pixels = &scene.pixels;
    let file_error = |detail: String| SceneError::File { path: path.to_path_buf(), detail };
    for instance in pixels.instances().map_or(&[][..], |found| &found.instances) {
        let keys = instance.trajectory.keys().iter().map(|key| &key.from_reference);
        if !(instance.placement.is_valid() && keys.into_iter().all(RigidMotion::is_finite)) {
            return Err(file_error(format!("instance {}: a pose or the placement is not finite", instance.id)));
        }
    }
    let mut tensors: Vec<(String, Vec<usize>, Dtype, Vec<u8>)> = Vec::new();
    let mut push_f32 = |name: &str, tensor: Tensor<2>| -> Result<(), SceneError> {
        let shape = tensor.dims().to_vec();
        let values = host_f32(tensor, name)?;
        // A file it could not read back is not written.
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let row = i / shape.get(1).copied().unwrap_or(1).max(1);
            return Err(file_error(format!(
                "`{name}`: value {} at row {row} is not finite: nothing written",
                values[i]
            )));
        }
        tensors.push((name.into(), shape, Dtype::F32, values.iter().flat_map(|v| v.to_le_bytes()).collect()));
        Ok(())
    };
    let column = |tensor: &Tensor<1>| tensor.clone().unsqueeze_dim::<2>(1);
    push_f32("pixels.means", pixels.means.clone())?;
    push_f32("pixels.quats_wxyz", pixels.quats_wxyz.clone())?;
    push_f32("pixels.scales", pixels.scales.clone())?;
    push_f32("pixels.colors", pixels.colors.clone())?;
    push_f32("pixels.opacity", column(&pixels.opacity))?;
    push_f32("pixels.lifespan", column(&pixels.lifespan))?;
    push_f32("pixels.source_time", column(&pixels.source_time))?;
    if let Some(logit) = &pixels.dynamic_logit {
        push_f32("pixels.dynamic_logit", column(logit))?;
    }
    if let Some(velocity) = &pixels.velocity {
        push_f32("pixels.velocity", velocity.clone())?;
    }
    if let Some(flow) = pixels.learnt() {
        push_f32("pixels.flow_to_next", flow.to_next.clone())?;
        push_f32("pixels.flow_to_previous", flow.to_previous.clone())?;
    }
    if let Some(sky) = &scene.sky {
        push_f32("sky.means", sky.means.clone())?;
        push_f32("sky.quats_wxyz", sky.quats.clone())?;
        push_f32("sky.scales", sky.scales.clone())?;
        push_f32("sky.colors", sky.colors.clone())?;
        push_f32("sky.opacities", column(&sky.opacities))?;
    }
    if let Some(instances) = pixels.instances() {
        let labels: Vec<u8> =
            (0..pixels.views.len()).flat_map(|v| instances.labels(v).iter().flat_map(|l| l.to_le_bytes())).collect();
        tensors.push(("instances.labels".into(), vec![pixels.views.len(), pixels.per_view()], Dtype::U32, labels));
    }
    let record = scene_record(scene);
    let views = tensors.iter().map(|(name, shape, dtype, bytes)| {
        let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes).expect("shapes and bytes agree");
        (name.clone(), view)
    });
    let metadata =
        HashMap::from([(METADATA_KEY.to_string(), serde_json::to_string(&record).expect("records serialise"))]);
    let bytes = safetensors::serialize(views, Some(metadata)).map_err(|e| file_error(e.to_string()))?;
    dggt_data::io::write_atomically(path, &bytes).map_err(|e| file_error(e.to_string()))
}

fn scene_record(scene: &Scene4d) -> SceneRecord {
    let pixels = &scene.pixels;
    let views = pixels
        .views
        .iter()
        .map(|view| {
            let rows = view.camera.world_from_camera.to_rows();
            let k = &view.camera.intrinsics;
            ViewRecord {
                rig_camera: view.rig_camera,
                time: view.time,
                world_from_camera: [rows[0], rows[1], rows[2]],
                intrinsics: [k.fx, k.fy, k.cx, k.cy],
            }
        })
        .collect();
    let assembly = &scene.assembly;
    SceneRecord {
        version: FORMAT_VERSION,
        size: [pixels.size.width, pixels.size.height],
        views,
        instances: pixels.instances().map(|found| found.instances.iter().map(instance_record).collect()),
        assembly: AssemblyRecord {
            dynamic_blend: assembly.dynamic_blend,
            dynamic_motion: assembly.dynamic_motion,
            eps2d: assembly.eps2d,
            near_plane: assembly.near_plane,
            far_plane: assembly.far_plane,
        },
    }
}

fn instance_record(instance: &Instance) -> InstanceRecord {
    InstanceRecord {
        id: instance.id,
        appearances: instance
            .appearances
            .iter()
            .map(|a| AppearanceRecord {
                time: a.time,
                views: a.views.clone(),
                pixels: a.pixels,
                box_min: a.bounds[0].to_array(),
                box_max: a.bounds[1].to_array(),
                centre: a.centre.to_array(),
            })
            .collect(),
        reference_centre: instance.trajectory.reference_centre().to_array(),
        keys: instance
            .trajectory
            .keys()
            .iter()
            .map(|key| KeyRecord { time: key.time, from_reference: (&key.from_reference).into() })
            .collect(),
        residuals: instance.residuals.clone(),
        placement: {
            let t = instance.placement.turn;
            PlacementRecord { turn_wxyz: [t.w, t.x, t.y, t.z], offset: instance.placement.offset.to_array() }
        },
    }
}

/// Reads a scene written by [`save_scene`] onto `device`.
pub fn load_scene(path: &Path, device: &Device) -> Result<Scene4d, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::File { path: path.into(), detail: e.to_string() })?;
    Reader::new(path, &bytes)?.scene(device)
}

/// A saved scene being read: the file's tensors and record.
struct Reader<'a> {
    path: PathBuf,
    tensors: SafeTensors<'a>,
    record: SceneRecord,
}

impl<'a> Reader<'a> {
    fn new(path: &Path, bytes: &'a [u8]) -> Result<Self, SceneError> {
        let error = |detail: String| SceneError::File { path: path.into(), detail };
        let (_, metadata) =
            SafeTensors::read_metadata(bytes).map_err(|e| error(format!("not a safetensors file: {e}")))?;
        let text = metadata
            .metadata()
            .as_ref()
            .and_then(|m| m.get(METADATA_KEY))
            .ok_or_else(|| error(format!("no `{METADATA_KEY}` record: not a saved scene")))?;
        let record: SceneRecord =
            serde_json::from_str(text).map_err(|e| error(format!("`{METADATA_KEY}` record: {e}")))?;
        if record.version != FORMAT_VERSION {
            return Err(error(format!("format version {}, this build reads {FORMAT_VERSION}", record.version)));
        }
        let tensors = SafeTensors::deserialize(bytes).map_err(|e| error(e.to_string()))?;
        Ok(Self { path: path.into(), tensors, record })
    }

    fn error(&self, detail: String) -> SceneError {
        SceneError::File { path: self.path.clone(), detail }
    }

    fn scene(&self, device: &Device) -> Result<Scene4d, SceneError> {
        let [width, height] = self.record.size;
        let size = ImageSize::new(width, height).map_err(|e| self.error(format!("size: {e}")))?;
        let views = self.views()?;
        let count = views.len() * size.area();
        let rows = |name: &str, columns: usize| self.f32_tensor(name, count, columns, device);
        let optional = |name: &str, columns: usize| -> Result<Option<Tensor<2>>, SceneError> {
            match self.tensors.tensor(name) {
                Ok(_) => rows(name, columns).map(Some),
                Err(_) => Ok(None),
            }
        };
        let flat = |tensor: Tensor<2>| tensor.reshape([count]);
        let pixels = PixelGaussians::from_saved(
            views,
            size,
            crate::pixels::SavedRows {
                means: rows("pixels.means", 3)?,
                quats_wxyz: rows("pixels.quats_wxyz", 4)?,
                scales: rows("pixels.scales", 3)?,
                colors: rows("pixels.colors", self.columns("pixels.colors")?)?,
                opacity: flat(rows("pixels.opacity", 1)?),
                lifespan: flat(rows("pixels.lifespan", 1)?),
                source_time: flat(rows("pixels.source_time", 1)?),
                dynamic_logit: optional("pixels.dynamic_logit", 1)?.map(flat),
                velocity: optional("pixels.velocity", 3)?,
            },
        )?;
        let pixels = match self.instances(pixels.views.len(), size.area())? {
            Some(instances) => pixels.with_known_instances(Arc::new(instances))?,
            None => pixels,
        };
        let pixels = match (optional("pixels.flow_to_next", 3)?, optional("pixels.flow_to_previous", 3)?) {
            (Some(to_next), Some(to_previous)) => pixels.with_known_learnt_flow(to_next, to_previous, None)?,
            (None, None) => pixels,
            _ => {
                return Err(self.error("holds one of `pixels.flow_to_next` and `pixels.flow_to_previous` alone".into()));
            }
        };
        let record = &self.record.assembly;
        let assembly = AssemblySettings {
            dynamic_blend: record.dynamic_blend,
            dynamic_motion: record.dynamic_motion,
            eps2d: record.eps2d,
            near_plane: record.near_plane,
            far_plane: record.far_plane,
            ..AssemblySettings::default()
        };
        Ok(Scene4d { pixels, sky: self.sky(device)?, assembly })
    }

    fn views(&self) -> Result<Vec<InputView>, SceneError> {
        if self.record.views.is_empty() {
            return Err(self.error("no input views".into()));
        }
        self.record
            .views
            .iter()
            .enumerate()
            .map(|(v, view)| {
                let invalid = |e: dggt_geom::GeomError| self.error(format!("view {v}: {e}"));
                let [fx, fy, cx, cy] = view.intrinsics;
                let camera = PosedCamera {
                    world_from_camera: WorldFromCamera::from_rows_3x4(view.world_from_camera).map_err(invalid)?,
                    intrinsics: PinholeIntrinsics::new(fx, fy, cx, cy).map_err(invalid)?,
                };
                if !view.time.is_finite() {
                    return Err(self.error(format!("view {v}: time {} is not finite", view.time)));
                }
                Ok(InputView { rig_camera: view.rig_camera, time: view.time, camera })
            })
            .collect()
    }

    /// The number of columns of the two-dimensional tensor `name` (colours have as many as the scene's layout).
    fn columns(&self, name: &str) -> Result<usize, SceneError> {
        let view = self.tensors.tensor(name).map_err(|_| self.error(format!("no tensor `{name}`")))?;
        match view.shape() {
            [_, columns] if *columns > 0 => Ok(*columns),
            shape => Err(self.error(format!("`{name}`: expected [rows, channels], found {shape:?}"))),
        }
    }

    /// The little-endian 4-byte values of tensor `name`, which must be of type `dtype` and shape `[rows, columns]`.
    fn words(&self, name: &str, dtype: Dtype, rows: usize, columns: usize) -> Result<Vec<[u8; 4]>, SceneError> {
        let view = self.tensors.tensor(name).map_err(|_| self.error(format!("no tensor `{name}`")))?;
        if view.dtype() != dtype || view.shape() != [rows, columns] {
            return Err(self.error(format!(
                "`{name}`: expected {dtype:?} {:?}, found {:?} {:?}",
                [rows, columns],
                view.dtype(),
                view.shape()
            )));
        }
        Ok(view.data().chunks_exact(4).map(|b| b.try_into().expect("four bytes")).collect())
    }

    /// The tensor `name` as `[rows, columns]` f32, every value finite.
    fn f32_tensor(&self, name: &str, rows: usize, columns: usize, device: &Device) -> Result<Tensor<2>, SceneError> {
        let values: Vec<f32> =
            self.words(name, Dtype::F32, rows, columns)?.into_iter().map(f32::from_le_bytes).collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.error(format!("`{name}`: value {} at row {} is not finite", values[i], i / columns)));
        }
        Ok(Tensor::from_data(TensorData::new(values, [rows, columns]), device))
    }

    fn sky(&self, device: &Device) -> Result<Option<SkyGaussians>, SceneError> {
        let Ok(means) = self.tensors.tensor("sky.means") else { return Ok(None) };
        let count = means.shape().first().copied().unwrap_or(0);
        let rows = |name: &str, columns: usize| self.f32_tensor(name, count, columns, device);
        Ok(Some(SkyGaussians {
            visible_index: (0..count).collect(),
            rgb_mean: Tensor::zeros([count, 3], device),
            field_out: Tensor::zeros([count, 6], device),
            colors: rows("sky.colors", 3)?,
            means: rows("sky.means", 3)?,
            scales: rows("sky.scales", 3)?,
            quats: rows("sky.quats_wxyz", 4)?,
            opacities: rows("sky.opacities", 1)?.reshape([count]),
        }))
    }

    /// The instances and their labels, when the file has them.
    fn instances(&self, views: usize, per_view: usize) -> Result<Option<Instances>, SceneError> {
        let Some(records) = &self.record.instances else { return Ok(None) };
        let values: Vec<u32> =
            self.words("instances.labels", Dtype::U32, views, per_view)?.into_iter().map(u32::from_le_bytes).collect();
        let labels = values.chunks_exact(per_view).map(<[u32]>::to_vec).collect();
        let instances = records.iter().map(|record| self.instance(record)).collect::<Result<Vec<_>, _>>()?;
        Instances::from_parts(instances, labels)
            .map(Some)
            .ok_or_else(|| self.error(format!("`instances.labels` names an instance beyond the {}", records.len())))
    }

    fn instance(&self, record: &InstanceRecord) -> Result<Instance, SceneError> {
        let keys = record.keys.iter().map(|k| KeyPose { time: k.time, from_reference: k.from_reference.motion() });
        let trajectory =
            Trajectory::from_keys(DVec3::from_array(record.reference_centre), keys.collect()).ok_or_else(|| {
                self.error(format!("instance {}: trajectory keys not finite or not at increasing times", record.id))
            })?;
        let [w, x, y, z] = record.placement.turn_wxyz;
        let placement =
            Placement { turn: DQuat::from_xyzw(x, y, z, w), offset: DVec3::from_array(record.placement.offset) };
        if !placement.is_valid() {
            return Err(self.error(format!(
                "instance {}: placement {:?} is not a rigid change (finite, a unit quaternion w x y z)",
                record.id, record.placement
            )));
        }
        let appearances = record
            .appearances
            .iter()
            .map(|a| Appearance {
                time: a.time,
                views: a.views.clone(),
                pixels: a.pixels,
                bounds: [DVec3::from_array(a.box_min), DVec3::from_array(a.box_max)],
                centre: DVec3::from_array(a.centre),
            })
            .collect();
        Ok(Instance { id: record.id, appearances, trajectory, residuals: record.residuals.clone(), placement })
    }
}
