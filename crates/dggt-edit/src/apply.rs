//! The edits applied to a saved scene. Every argument is checked (ids, sources, layouts) before anything
//! changes, so a bad edit leaves nothing half done.
//!
//! - **Remove**: the instance's Gaussians get zero opacity in every view (static and dynamic parts alike), so
//!   whatever other views and times saw behind it shows through.
//! - **Move**: the instance's placement ([`Placement`]) turns it about its centre and shifts it at every time;
//!   two moves of one instance add up (turns composed, offsets summed).
//! - **Insert**: an instance of another saved scene, carried into this world ([`CarriedObject`]).
//! - **Remove a box**: every Gaussian whose mean lies in a world-axis-aligned box gets zero opacity (static
//!   objects, which are no instance: a parked car, a sign).
//!
//! An edited instance first takes in its soft fringe: pixels within [`FRINGE_PIXELS`] of its labelled pixels
//! whose dynamic probability is at least [`FRINGE_PROBABILITY`] (the object's outline, which the instance
//! labels at probability one half leave out), so that a removed or moved car leaves no outline behind.

use std::collections::BTreeMap;
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::DVec3;
use dggt_instances::{Instances, Placement, RigidMotion};
use dggt_model::host::host_f32;
use dggt_scene::{DynamicMotion, Scene4d, TargetView, ViewRender, load_scene};
use dggt_splat::{GaussianTensors, OpacityTensor};

use crate::error::EditError;
use crate::frame::WorldUp;
use crate::object::{CarriedObject, shared_opacity, tensors};
use crate::request::{Edit, EditKind, Insertion};

/// How far (4-neighbour steps) an edited instance grows into its fringe.
pub const FRINGE_PIXELS: usize = 2;
/// The least dynamic probability of a fringe pixel.
pub const FRINGE_PROBABILITY: f32 = 0.1;
/// The dynamic logit a moved instance's pixels get at least: its static share `1 - sigmoid(12)` is below
/// `1e-5`, so no copy of it stays where it was.
pub const WHOLLY_DYNAMIC_LOGIT: f32 = 12.0;

/// A scene with its edits applied.
#[derive(Debug, Clone)]
pub struct EditedScene {
    /// The scene as saved (its assembly switched to instance motion when a move needs it): the "before".
    pub original: Scene4d,
    /// The scene with its instances removed or moved.
    pub edited: Scene4d,
    /// Objects inserted from other scenes.
    pub carried: Vec<CarriedObject>,
    pub up: WorldUp,
}

impl EditedScene {
    /// The edited scene rendered at `target`.
    pub fn render(&self, target: &TargetView) -> Result<ViewRender, EditError> {
        let assembled = self.gaussians(target)?;
        Ok(self.edited.render_assembled(&assembled, target)?)
    }

    /// The Gaussians the edited scene draws at `target` (the scene's own, culled, and the inserted ones).
    pub fn gaussians(&self, target: &TargetView) -> Result<dggt_scene::AssembledGaussians, EditError> {
        let mut assembled = self.edited.assemble(target)?;
        let device = assembled.gaussians.means.device();
        for object in &self.carried {
            let cloud = object.cloud_at(target.time);
            if !cloud.is_empty() {
                assembled.gaussians = concatenated(assembled.gaussians, tensors(&cloud, &device));
            }
        }
        Ok(assembled)
    }
}

fn concatenated(a: GaussianTensors, b: GaussianTensors) -> GaussianTensors {
    GaussianTensors {
        means: Tensor::cat(vec![a.means, b.means], 0),
        quats_wxyz: Tensor::cat(vec![a.quats_wxyz, b.quats_wxyz], 0),
        scales: Tensor::cat(vec![a.scales, b.scales], 0),
        opacities: OpacityTensor::Shared(Tensor::cat(
            vec![shared_opacity(a.opacities), shared_opacity(b.opacities)],
            0,
        )),
        colors: Tensor::cat(vec![a.colors, b.colors], 0),
    }
}

/// Applies `edits` to `scene` (sources of insertions read onto `device`).
pub fn apply_edits(mut scene: Scene4d, edits: &[Edit], device: &Device) -> Result<EditedScene, EditError> {
    let up = WorldUp::of_camera(&scene.views()[0].camera);
    let changes = instance_changes(&scene, up, edits)?;
    let carried = edits
        .iter()
        .filter_map(|edit| match &edit.kind {
            EditKind::Insert(insertion) => Some(carry(&scene, up, &edit.argument, insertion, device)),
            _ => None,
        })
        .collect::<Result<Vec<_>, _>>()?;
    if changes.values().any(|change| matches!(change, Change::Move(_))) {
        scene.assembly.dynamic_motion = DynamicMotion::Instances;
    }
    let boxes: Vec<[DVec3; 2]> = edits
        .iter()
        .filter_map(|edit| match edit.kind {
            EditKind::RemoveBox { min, max } => Some([min, max]),
            _ => None,
        })
        .collect();
    let edited =
        if changes.is_empty() && boxes.is_empty() { scene.clone() } else { changed(&scene, &changes, &boxes)? };
    Ok(EditedScene { original: scene, edited, carried, up })
}

/// What happens to one instance of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Change {
    Remove,
    Move(Placement),
}

/// The change of every edited instance (by position), each id checked.
fn instance_changes(scene: &Scene4d, up: WorldUp, edits: &[Edit]) -> Result<BTreeMap<usize, Change>, EditError> {
    let mut changes: BTreeMap<usize, Change> = BTreeMap::new();
    for edit in edits {
        let Some(id) = edit.target_instance() else { continue };
        let position = instance_position(scene, id, &edit.argument)?;
        let change = match edit.kind {
            EditKind::Move { offset, yaw_degrees, .. } => Change::Move(Placement { turn: up.yaw(yaw_degrees), offset }),
            _ => Change::Remove,
        };
        let merged = match (changes.get(&position), change) {
            (None, change) => change,
            (Some(Change::Move(first)), Change::Move(second)) => {
                Change::Move(Placement { turn: second.turn * first.turn, offset: first.offset + second.offset })
            }
            _ => {
                return Err(EditError::argument(
                    &edit.argument,
                    format!("instance {id} is both removed and edited otherwise"),
                ));
            }
        };
        changes.insert(position, merged);
    }
    Ok(changes)
}

/// The position in `scene`'s instance list of instance `id`.
fn instance_position(scene: &Scene4d, id: u32, argument: &str) -> Result<usize, EditError> {
    let found = scene.pixels.instances().ok_or_else(|| {
        EditError::argument(argument, "the scene has no moving objects (its network has no dynamic head)")
    })?;
    found.instances.iter().position(|instance| instance.id == id).ok_or_else(|| {
        let ids: Vec<u32> = found.instances.iter().map(|instance| instance.id).collect();
        EditError::argument(argument, format!("no instance {id}; the scene has {} ({ids:?})", ids.len()))
    })
}

/// `scene` with its instances grown into their fringes, removed ones and the Gaussians in removed boxes
/// transparent, moved ones placed and made wholly dynamic (so that no static copy stays behind).
fn changed(scene: &Scene4d, changes: &BTreeMap<usize, Change>, boxes: &[[DVec3; 2]]) -> Result<Scene4d, EditError> {
    let pixels = &scene.pixels;
    let per_view = pixels.per_view();
    let mut logit = match &pixels.dynamic_logit {
        Some(logit) => Some(host_f32(logit.clone(), "dynamic logit")?),
        None => None,
    };
    let mut keep = vec![1.0f32; pixels.len()];
    for (row, mean) in pixels.host_means().iter().enumerate() {
        let mean = DVec3::from_array(mean.map(f64::from));
        if boxes.iter().any(|[low, high]| mean.cmpge(*low).all() && mean.cmple(*high).all()) {
            keep[row] = 0.0;
        }
    }
    let mut instances = pixels.instances().map(|found| found.instances.clone()).unwrap_or_default();
    let labels = grown_labels(scene, changes, logit.as_deref());
    for (&position, change) in changes {
        let rows = labels.iter().enumerate().flat_map(|(view, labels)| {
            labels
                .iter()
                .enumerate()
                .filter(move |(_, l)| **l as usize == position)
                .map(move |(p, _)| view * per_view + p)
        });
        match change {
            Change::Remove => rows.for_each(|row| keep[row] = 0.0),
            Change::Move(placement) => {
                instances[position].placement = *placement;
                if let Some(logit) = logit.as_mut() {
                    rows.for_each(|row| logit[row] = logit[row].max(WHOLLY_DYNAMIC_LOGIT));
                }
            }
        }
    }
    let mut edited = scene.clone();
    let device = pixels.opacity.device();
    let count = pixels.len();
    edited.pixels.opacity = pixels.opacity.clone() * Tensor::from_data(TensorData::new(keep, [count]), &device);
    if let Some(logit) = logit {
        edited.pixels.dynamic_logit = Some(Tensor::from_data(TensorData::new(logit, [count]), &device));
    }
    if !labels.is_empty() {
        let instances = Instances::from_parts(instances, labels).expect("labels name the same instances");
        edited.pixels = edited.pixels.with_known_instances(Arc::new(instances))?;
    }
    Ok(edited)
}

/// The scene's instance labels with every changed instance grown into its fringe; empty without instances.
fn grown_labels(scene: &Scene4d, changes: &BTreeMap<usize, Change>, logit: Option<&[f32]>) -> Vec<Vec<u32>> {
    let pixels = &scene.pixels;
    let Some(found) = pixels.instances() else { return Vec::new() };
    let (width, height) = (pixels.size.width as usize, pixels.size.height as usize);
    let mut labels: Vec<Vec<u32>> = (0..found.views()).map(|view| found.labels(view).to_vec()).collect();
    let Some(logit) = logit else { return labels };
    for (view, labels) in labels.iter_mut().enumerate() {
        let probability: Vec<f32> = logit[view * width * height..(view + 1) * width * height]
            .iter()
            .map(|l| 1.0 / (1.0 + (-l).exp()))
            .collect();
        for &position in changes.keys() {
            grow(labels, position as u32, &probability, width, height);
        }
    }
    labels
}

/// Grows the pixels labelled `label` by [`FRINGE_PIXELS`] 4-neighbour steps over unlabelled pixels whose
/// dynamic probability is at least [`FRINGE_PROBABILITY`].
fn grow(labels: &mut [u32], label: u32, probability: &[f32], width: usize, height: usize) {
    let mut frontier: Vec<usize> = (0..labels.len()).filter(|&p| labels[p] == label).collect();
    for _ in 0..FRINGE_PIXELS {
        let mut next = Vec::new();
        for &pixel in &frontier {
            let (column, row) = (pixel % width, pixel / width);
            let neighbours = [
                (column > 0).then(|| pixel - 1),
                (column + 1 < width).then(|| pixel + 1),
                (row > 0).then(|| pixel - width),
                (row + 1 < height).then(|| pixel + width),
            ];
            for neighbour in neighbours.into_iter().flatten() {
                if labels[neighbour] == Instances::NONE && probability[neighbour] >= FRINGE_PROBABILITY {
                    labels[neighbour] = label;
                    next.push(neighbour);
                }
            }
        }
        frontier = next;
    }
}

/// The object of an `--insert`, read from its scene and mapped into this one.
fn carry(
    destination: &Scene4d,
    up: WorldUp,
    argument: &str,
    insertion: &Insertion,
    device: &Device,
) -> Result<CarriedObject, EditError> {
    let Insertion { source, instance: id, position, yaw_degrees } = insertion;
    let (id, position, yaw_degrees) = (*id, *position, *yaw_degrees);
    let file = dggt_scene::scene_file(source);
    let scene = load_scene(&file, device).map_err(|e| EditError::argument(argument, e.to_string()))?;
    let layout = |scene: &Scene4d| scene.pixels.colors.dims()[1];
    if layout(&scene) != layout(destination) {
        return Err(EditError::argument(
            argument,
            format!(
                "{} has {} colour channels per Gaussian, this scene {}: the Gaussian layouts differ",
                file.display(),
                layout(&scene),
                layout(destination)
            ),
        ));
    }
    let index = instance_position(&scene, id, argument)?;
    let centre = scene.pixels.instances().expect("checked").instances[index].trajectory.reference_centre();
    let rotation = up.yaw(yaw_degrees) * up.turn_from(WorldUp::of_camera(&scene.views()[0].camera));
    let to_destination = RigidMotion { rotation, translation: position - rotation * centre };
    CarriedObject::take(&scene, index, to_destination, argument)
}
