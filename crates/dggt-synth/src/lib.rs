//! Synthetic driving scenes: a procedural street rendered by an analytic ray caster and written in the
//! scene-export layout, so that the whole pipeline can be exercised and checked without real data.
//!
//! The scene (road with lane markings, raised sidewalks, textured buildings, poles, trees, parked cars, a
//! structured sky, and moving cars on analytic trajectories, one of them turning) is independent of any Gaussian
//! rasteriser: colours, masks, depth and scene flow come from exact ray-primitive intersections, so they are
//! ground truth. Everything is a pure function of [`SynthConfig`] and the edits applied ([`edit`]); the same
//! arguments give byte-identical files. The world is metric with z up, x along the road (the ego's direction of
//! travel at the first frame, whose ego pose is the identity) and y to the left.
//!
//! - [`config`]: the arguments and their validation.
//! - [`generate()`]: the seeded layout, producing a [`SynthScene`].
//! - [`scene`]: objects and ray casting ([`SynthScene::cast`], [`SceneAt`]).
//! - [`change`]: what an edit does to one object ([`WorldChange`], [`ObjectEdit`]) and where the edited scene
//!   draws it ([`Presence`]); [`edit`]: edited copies of a scene ([`SynthScene::edited`]), objects removed or
//!   rigidly moved, as ground truth for scene editing.
//! - [`motion`], [`rig`], [`street`]: ego and car trajectories, the camera rig, the street's cross-section.
//! - [`render`]: one view's colours, masks and depth-flow; [`lidar`]: the ego vehicle's lidar sweeps.
//! - [`export`]: the files written ([`synthesize`], [`write_export`]) in any export variant, and their
//!   conventions.

pub mod change;
pub mod config;
pub mod edit;
mod error;
pub mod export;
mod generate;
mod grid;
pub mod lidar;
pub mod motion;
mod noise;
mod object_id;
pub mod render;
pub mod rig;
pub mod scene;
mod shading;
mod shapes;
pub mod street;

pub use change::{ObjectEdit, Presence, WorldChange};
pub use config::SynthConfig;
pub use edit::MoveFlag;
pub use error::{Result, SynthError};
pub use export::{Sweeps, SynthSummary, largest_output_bytes, synthesize, write_export};
pub use generate::generate;
pub use motion::{CarMotion, CarState, EgoMotion, Object, Path, WorldFromObject};
pub use object_id::ObjectId;
pub use render::RenderedView;
pub use rig::RigCamera;
pub use scene::{Hit, ObjectKind, SceneAt, SceneObject, SynthScene};
pub use shapes::Aabb;
