//! The edits applied to a saved scene. Every argument is checked (ids, sources, layouts) before anything
//! changes, so a bad edit leaves nothing half done.
//!
//! - **Remove**: the instance's Gaussians get zero opacity in every view (static and dynamic parts alike), so
//!   whatever other views and times saw behind it shows through.
//! - **Move**: the instance's placement ([`Placement`]) turns it about its centre and shifts it at every time;
//!   two moves of one instance add up (turns composed, offsets summed).
//! - **Insert**: an instance of another saved scene, carried into this world ([`CarriedObject`]).
//!
//! An edited instance first takes in its soft fringe: pixels within [`FRINGE_PIXELS`] of its labelled pixels
//! whose dynamic probability is at least [`FRINGE_PROBABILITY`] (the object's outline, which the instance
//! labels at probability one half leave out), so that a removed or moved car leaves no outline behind.

use std::collections::BTreeMap;
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
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
    let opacity = shared_opacity;
    GaussianTensors {
        means: Tensor::cat(vec![a.means, b.means], 0),
        quats_wxyz: Tensor::cat(vec![a.quats_wxyz, b.quats_wxyz], 0),
        scales: Tensor::cat(vec![a.scales, b.scales], 0),
        opacities: OpacityTensor::Shared(Tensor::cat(vec![opacity(a.opacities), opacity(b.opacities)], 0)),
        colors: Tensor::cat(vec![a.colors, b.colors], 0),
    }
}

/// Applies `edits` to `scene` (sources of insertions read onto `device`).
pub fn apply_edits(mut scene: Scene4d, edits: &[Edit], device: &Device) -> Result<EditedScene, EditError> {
    let up = WorldUp::of_camera(&scene.views()[0].camera);
    let changes = instance_changes(&scene, edits)?;
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
    let edited = if changes.is_empty() { scene.clone() } else { changed(&scene, &changes)? };
    Ok(EditedScene { original: scene, edited, carried, up })
}

/// What happens to one instance of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Change {
    Remove,
    Move(Placement),
}

/// The change of every edited instance (by position), each id checked.
fn instance_changes(scene: &Scene4d, edits: &[Edit]) -> Result<BTreeMap<usize, Change>, EditError> {
    let up = WorldUp::of_camera(&scene.views()[0].camera);
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

/// `scene` with its instances grown into their fringes, removed ones transparent and moved ones placed.
fn changed(scene: &Scene4d, changes: &BTreeMap<usize, Change>) -> Result<Scene4d, EditError> {
    let pixels = &scene.pixels;
    let found = pixels.instances().expect("edited instances exist");
    let dynamic = match &pixels.dynamic_logit {
        Some(logit) => host_f32(burn::tensor::activation::sigmoid(logit.clone()), "dynamic probability")?,
        None => vec![0.0; pixels.len()],
    };
    let (width, height) = (pixels.size.width as usize, pixels.size.height as usize);
    let mut labels: Vec<Vec<u32>> = (0..found.views()).map(|view| found.labels(view).to_vec()).collect();
    for (view, labels) in labels.iter_mut().enumerate() {
        let probability = &dynamic[view * width * height..(view + 1) * width * height];
        for &position in changes.keys() {
            grow(labels, position as u32, probability, width, height);
        }
    }
    let mut instances = found.instances.clone();
    let mut keep = vec![1.0f32; pixels.len()];
    for (&position, change) in changes {
        match change {
            Change::Move(placement) => instances[position].placement = *placement,
            Change::Remove => {
                for (view, labels) in labels.iter().enumerate() {
                    for (pixel, _) in labels.iter().enumerate().filter(|(_, l)| **l as usize == position) {
                        keep[view * width * height + pixel] = 0.0;
                    }
                }
            }
        }
    }
    let instances = Instances::from_parts(instances, labels).expect("labels name the same instances");
    let mut edited = scene.clone();
    let device = pixels.opacity.device();
    edited.pixels.opacity = pixels.opacity.clone() * Tensor::from_data(TensorData::new(keep, [pixels.len()]), &device);
    edited.pixels = edited.pixels.with_known_instances(Arc::new(instances))?;
    Ok(edited)
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
    let file = if source.is_dir() { source.join(dggt_scene::SCENE_FILE) } else { source.to_path_buf() };
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
