//! Moving objects of one forward pass, found without an external tracker: the dynamic pixels of every input
//! view grouped into objects, each object followed through the input times, and its rigid motion between
//! consecutive times registered from its points, so that it can be drawn at any time in between.
//!
//! The data flow, one module per step:
//!
//! 1. [`cluster`]: each view's dynamic pixels as connected components of one surface (pixel-grid neighbours
//!    without a depth edge between them);
//! 2. [`link`]: the components of one input time that overlap joined into one object (an occluded car's
//!    parts, the same car in two cameras), and objects followed from one input time to the next;
//! 3. [`register`]: the rigid motion of an object between consecutive times, by trimmed iterative closest
//!    points seeded by the network's predicted motion where it has one ([`rigid`]: the closed-form fit);
//! 4. [`trajectory`]: the object's key poses at the input times, interpolated between them (centre linear,
//!    rotation SLERP);
//! 5. [`instances`]: all of it as [`Instances`], ids, per-time boxes and pixel labels.
//!
//! Conventions: points and motions in the reconstruction's world axes and units (whatever scale the network
//! predicted); times in scene time; quaternions `w x y z` when written out; a motion maps world points at one
//! time to world points at another.

pub mod cluster;
pub mod instances;
pub mod link;
pub mod register;
pub mod rigid;
pub mod trajectory;
mod union_find;

pub use cluster::{Cluster, ClusterSettings, ViewPoints, cluster_view};
pub use instances::{Appearance, Instance, InstanceSettings, Instances, Placement, ShapeError, find_instances};
pub use link::LinkSettings;
pub use register::{Registration, RegistrationSettings, register};
pub use rigid::{RigidMotion, fit_rigid};
pub use trajectory::{KeyPose, Trajectory};
