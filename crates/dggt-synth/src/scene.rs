//! The in-memory scene and ray casting through it.
//!
//! A [`SynthScene`] holds the static objects, the moving cars with their trajectories, the ego trajectory and
//! the camera rig. [`SceneAt`] is the scene frozen at one instant (every object placed), which is what rays are
//! cast against: [`SceneAt::cast`] returns the nearest surface with its distance, object, motion and colour.
//! An object removed by an edit ([`crate::edit`]) is never placed; a moved one is placed where the edit puts it
//! ([`Presence`]).

use dggt_geom::glam::DVec3;
use dggt_geom::{ImageSize, PinholeIntrinsics, Rigid, World, WorldFromCamera, WorldFromEgo};
use serde::Serialize;

use crate::change::Presence;
use crate::config::SynthConfig;
use crate::grid::StreetGrid;
use crate::motion::{CarMotion, CarState, Object, WorldFromObject};
use crate::object_id::ObjectId;
use crate::rig::RigCamera;
use crate::shading::{Material, Surface, albedo, lit, sky};
use crate::shapes::{Aabb, Shape, T_MIN};
use crate::street::Street;

/// Speed above which an object counts as dynamic (m/s), as the export's dynamic masks define it.
pub const MOVING_SPEED_THRESHOLD: f64 = 1.0;

/// What an object is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectKind {
    Ground,
    Sidewalk,
    Building,
    Pole,
    Tree,
    ParkedCar,
    MovingCar,
}

impl ObjectKind {
    /// Cars, parked or moving: the objects listed as instances.
    pub fn is_vehicle(self) -> bool {
        matches!(self, Self::ParkedCar | Self::MovingCar)
    }
}

/// One primitive of an object with its surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Part {
    pub shape: Shape,
    pub material: Material,
}

/// How an object is placed in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Placement {
    Fixed(WorldFromObject),
    Driving(CarMotion),
}

/// One object: primitives in its own frame, how that frame is placed in the world over time, and whether an
/// edit moved or removed it.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    pub(crate) id: ObjectId,
    pub(crate) kind: ObjectKind,
    pub(crate) parts: Vec<Part>,
    pub(crate) bounds: Aabb,
    pub(crate) placement: Placement,
    pub(crate) presence: Presence,
}

impl SceneObject {
    pub(crate) fn new(id: ObjectId, kind: ObjectKind, parts: Vec<Part>, placement: Placement) -> Self {
        let bounds = parts[1..].iter().fold(parts[0].shape.bounds(), |b, p| b.union(&p.shape.bounds()));
        Self { id, kind, parts, bounds, placement, presence: Presence::Generated }
    }

    pub fn id(&self) -> ObjectId {
        self.id
    }

    pub fn kind(&self) -> ObjectKind {
        self.kind
    }

    /// `[length, width, height]` of the enclosing box (m).
    pub fn box_size(&self) -> [f64; 3] {
        self.bounds.size().to_array()
    }

    /// Whether an edit moved or removed the object.
    pub fn presence(&self) -> Presence {
        self.presence
    }

    /// Whether the scene draws the object: false once an edit removed it.
    pub fn is_drawn(&self) -> bool {
        !matches!(self.presence, Presence::Removed)
    }

    /// The trajectory of a moving car as generated, before any move; `None` for static objects.
    pub fn motion(&self) -> Option<&CarMotion> {
        match &self.placement {
            Placement::Driving(motion) => Some(motion),
            Placement::Fixed(_) => None,
        }
    }

    /// A moving car's state at `time`, moved as an edit says; `None` for static objects.
    pub fn state(&self, time: f64) -> Option<CarState> {
        self.motion().map(|motion| self.moved_state(motion.state(time)))
    }

    fn moved_state(&self, state: CarState) -> CarState {
        match &self.presence {
            Presence::Moved(change) => change.after_state(&state),
            Presence::Generated | Presence::Removed => state,
        }
    }

    /// Object frame -> world at `time` (for cars: `obj_to_world`), moved as an edit says; a removed object
    /// keeps the pose it would have. Panics for a moving car if `time` is not finite.
    pub fn world_from_object(&self, time: f64) -> WorldFromObject {
        match (&self.placement, &self.presence) {
            (Placement::Fixed(pose), Presence::Moved(change)) => {
                change.after(pose).expect("edits are checked to be finite before they are applied")
            }
            (Placement::Fixed(pose), Presence::Generated | Presence::Removed) => *pose,
            (Placement::Driving(motion), _) => self.moved_state(motion.state(time)).world_from_object(),
        }
    }

    /// World centre (m) at `time` of the object's enclosing box: the natural pivot of a move. Panics for a
    /// moving car if `time` is not finite.
    pub fn centre(&self, time: f64) -> DVec3 {
        self.world_from_object(time).transform_point(self.box_centre())
    }

    /// The box centre at `time` where the generator placed it, before any move.
    pub(crate) fn generated_centre(&self, time: f64) -> DVec3 {
        let pose = match &self.placement {
            Placement::Fixed(pose) => *pose,
            Placement::Driving(motion) => motion.state(time).world_from_object(),
        };
        pose.transform_point(self.box_centre())
    }

    /// Centre of the enclosing box in the object frame.
    fn box_centre(&self) -> DVec3 {
        (self.bounds.min + self.bounds.max) * 0.5
    }

    /// World velocity (m/s) at `time` of the world point `point` attached to this object.
    pub fn point_velocity(&self, point: DVec3, time: f64) -> DVec3 {
        self.state(time).map_or(DVec3::ZERO, |state| state.point_velocity(point))
    }
}

/// A procedural driving scene: everything needed to render any frame from any camera.
#[derive(Debug, Clone)]
pub struct SynthScene {
    pub(crate) config: SynthConfig,
    pub(crate) size: ImageSize,
    pub(crate) intrinsics: PinholeIntrinsics,
    pub(crate) rig: Vec<RigCamera>,
    /// The rows written to `ego_pose/{t}.txt` and the poses read back from them.
    pub(crate) ego_pose_rows: Vec<[[f64; 4]; 4]>,
    pub(crate) world_from_ego: Vec<WorldFromEgo>,
    pub(crate) street: Street,
    pub(crate) objects: Vec<SceneObject>,
    pub(crate) sky_salt: u64,
}

impl SynthScene {
    pub fn config(&self) -> &SynthConfig {
        &self.config
    }

    pub fn image_size(&self) -> ImageSize {
        self.size
    }

    /// Intrinsics shared by every camera.
    pub fn intrinsics(&self) -> PinholeIntrinsics {
        self.intrinsics
    }

    pub fn rig(&self) -> &[RigCamera] {
        &self.rig
    }

    pub fn street(&self) -> &Street {
        &self.street
    }

    /// The ego pose of `frame` (ego -> world), as written to and read back from `ego_pose/{frame}.txt`.
    pub fn world_from_ego(&self, frame: usize) -> Option<WorldFromEgo> {
        self.world_from_ego.get(frame).copied()
    }

    /// The pose (OpenCV axes) of `camera` at `frame`: `world_from_ego · ego_from_camera`.
    pub fn world_from_camera(&self, frame: usize, camera: usize) -> Option<WorldFromCamera> {
        Some(self.world_from_ego(frame)? * self.rig.get(camera)?.ego_from_camera)
    }

    /// Every object, removed ones included ([`SceneObject::is_drawn`]); an object's id is its index.
    pub fn objects(&self) -> &[SceneObject] {
        &self.objects
    }

    /// The object `id`, removed or not.
    pub fn object(&self, id: ObjectId) -> Option<&SceneObject> {
        self.objects.get(id as usize)
    }

    /// The cars the scene draws (moving first, then parked): the instances of the export.
    pub fn instances(&self) -> impl Iterator<Item = &SceneObject> {
        self.objects.iter().filter(|o| o.kind.is_vehicle() && o.is_drawn())
    }

    /// The scene frozen at `time` (seconds); `None` when `time` is not finite.
    pub fn at(&self, time: f64) -> Option<SceneAt<'_>> {
        time.is_finite().then(|| SceneAt::new(self, time, |_| true))
    }

    /// The nearest surface along the ray from `origin` along `direction` (any length) at `time`, or `None` for
    /// sky (and for non-finite input). Builds a [`SceneAt`]; cast through [`SynthScene::at`] for many rays.
    pub fn cast(&self, origin: DVec3, direction: DVec3, time: f64) -> Option<Hit> {
        self.at(time)?.cast(origin, direction)
    }
}

/// The surface a ray hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Euclidean distance from the ray origin (m).
    pub distance: f64,
    /// World position of the hit.
    pub point: DVec3,
    /// Outward unit normal of the surface (world).
    pub normal: DVec3,
    pub object: ObjectId,
    pub kind: ObjectKind,
    /// Whether the object moves faster than [`MOVING_SPEED_THRESHOLD`].
    pub dynamic: bool,
    /// World velocity of the surface point (m/s); zero on static objects.
    pub velocity: DVec3,
    /// Shaded colour as seen along the ray, in `[0, 1]`.
    pub colour: [f32; 3],
}

/// One object placed at the scene's instant.
#[derive(Debug, Clone, Copy)]
struct Placed<'a> {
    object: &'a SceneObject,
    object_from_world: Rigid<Object, World>,
    world_from_object: WorldFromObject,
    world_box: Aabb,
    /// The object frame is the world frame: rays need no transform.
    in_world_frame: bool,
    state: Option<CarState>,
}

impl Placed<'_> {
    fn moving(&self) -> bool {
        self.state.is_some_and(|s| s.velocity.length() > MOVING_SPEED_THRESHOLD)
    }
}

/// The nearest intersection found by [`SceneAt::trace`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Trace {
    /// Distance along the unit ray direction.
    pub t: f64,
    placed: usize,
    part: usize,
    local_normal: DVec3,
}

/// The scene at one instant, with every object placed.
#[derive(Debug, Clone)]
pub struct SceneAt<'a> {
    scene: &'a SynthScene,
    time: f64,
    placed: Vec<Placed<'a>>,
    grid: StreetGrid,
    /// Indices of the objects moving faster than the threshold.
    moving: Vec<usize>,
}

impl<'a> SceneAt<'a> {
    /// Places every drawn object at `time` (finite), keeping those whose world box passes `keep`.
    pub(crate) fn new(scene: &'a SynthScene, time: f64, keep: impl Fn(&Aabb) -> bool) -> Self {
        let placed: Vec<Placed<'a>> = scene
            .objects
            .iter()
            .filter(|object| object.is_drawn())
            .filter_map(|object| {
                let state = object.state(time);
                let world_from_object = state.map_or_else(|| object.world_from_object(time), |s| s.world_from_object());
                let world_box = object.bounds.transformed(&world_from_object);
                keep(&world_box).then(|| Placed {
                    object,
                    object_from_world: world_from_object.inverse(),
                    world_from_object,
                    world_box,
                    in_world_frame: world_from_object == Rigid::IDENTITY,
                    state,
                })
            })
            .collect();
        let boxes: Vec<Aabb> = placed.iter().map(|p| p.world_box).collect();
        let moving = (0..placed.len()).filter(|&i| placed[i].moving()).collect();
        Self { scene, time, grid: StreetGrid::new(&boxes), placed, moving }
    }

    pub fn time(&self) -> f64 {
        self.time
    }

    /// The nearest surface along the ray from `origin` along `direction` (any non-zero length), or `None` for
    /// sky and for degenerate input.
    pub fn cast(&self, origin: DVec3, direction: DVec3) -> Option<Hit> {
        let dir = direction.try_normalize()?;
        if !origin.is_finite() {
            return None;
        }
        let trace = self.trace(origin, dir)?;
        let placed = &self.placed[trace.placed];
        let point = origin + dir * trace.t;
        Some(Hit {
            distance: trace.t,
            point,
            normal: placed.world_from_object.transform_vector(trace.local_normal),
            object: placed.object.id,
            kind: placed.object.kind,
            dynamic: self.is_dynamic(&trace),
            velocity: self.velocity(&trace, point),
            colour: self.colour(&trace, origin, dir).as_vec3().to_array(),
        })
    }

    /// The nearest intersection along the unit direction `dir`.
    pub(crate) fn trace(&self, origin: DVec3, dir: DVec3) -> Option<Trace> {
        let mut best: Option<Trace> = None;
        let mut best_t = f64::INFINITY;
        self.grid.traverse(origin, dir, |index| {
            let placed = &self.placed[index as usize];
            let Some((entry, exit, _)) = placed.world_box.interval(origin, dir) else { return best_t };
            if exit <= T_MIN || entry >= best_t {
                return best_t;
            }
            let (o, d) = if placed.in_world_frame {
                (origin, dir)
            } else {
                (placed.object_from_world.transform_point(origin), placed.object_from_world.transform_vector(dir))
            };
            for (part, shape) in placed.object.parts.iter().map(|p| &p.shape).enumerate() {
                if let Some((t, local_normal)) = shape.hit(o, d, best_t) {
                    best_t = t;
                    best = Some(Trace { t, placed: index as usize, part, local_normal });
                }
            }
            best_t
        });
        best
    }

    pub(crate) fn object(&self, trace: &Trace) -> &'a SceneObject {
        self.placed[trace.placed].object
    }

    /// Whether the traced surface belongs to an object moving faster than the threshold.
    pub(crate) fn is_dynamic(&self, trace: &Trace) -> bool {
        self.placed[trace.placed].moving()
    }

    /// World velocity of the traced surface point `point`.
    pub(crate) fn velocity(&self, trace: &Trace, point: DVec3) -> DVec3 {
        self.placed[trace.placed].state.map_or(DVec3::ZERO, |s| s.point_velocity(point))
    }

    /// The shaded colour of the traced surface seen along the unit direction `dir` from `origin`.
    pub(crate) fn colour(&self, trace: &Trace, origin: DVec3, dir: DVec3) -> DVec3 {
        let placed = &self.placed[trace.placed];
        let world = origin + dir * trace.t;
        let surface = Surface {
            world,
            local: if placed.in_world_frame { world } else { placed.object_from_world.transform_point(world) },
            local_normal: trace.local_normal,
        };
        let part = &placed.object.parts[trace.part];
        let normal = placed.world_from_object.transform_vector(trace.local_normal);
        lit(albedo(&part.material, &surface, &self.scene.street), normal, trace.t)
    }

    /// The sky colour along the unit direction `dir`.
    pub(crate) fn sky(&self, dir: DVec3) -> DVec3 {
        sky(dir, self.scene.sky_salt)
    }

    /// The moving cars (faster than the threshold) whose 3D box the ray crosses, whatever is in front: the
    /// projected-box dynamic mask.
    pub(crate) fn moving_boxes_crossed(&self, origin: DVec3, dir: DVec3) -> impl Iterator<Item = ObjectId> + '_ {
        self.moving.iter().filter_map(move |&index| {
            let placed = &self.placed[index];
            let o = placed.object_from_world.transform_point(origin);
            let d = placed.object_from_world.transform_vector(dir);
            let crossed = placed.object.bounds.interval(o, d).is_some_and(|(_, exit, _)| exit > T_MIN);
            crossed.then_some(placed.object.id)
        })
    }
}
