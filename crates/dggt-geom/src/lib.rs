//! Camera geometry for dggt.
//!
//! Every boundary in a driving-scene pipeline is a chance to mix up a convention: camera-from-world versus
//! world-from-camera, OpenCV versus vehicle axes, wxyz versus xyzw quaternions, pixel centres at integers versus
//! half-integers. This crate names each of these in a type so that the compiler keeps them apart:
//!
//! - [`Rigid<To, From>`](Rigid) maps points expressed in frame `From` into frame `To`; composition only
//!   type-checks when the frames chain (`Rigid<A, B> * Rigid<B, C> = Rigid<A, C>`).
//! - [`Camera`] axes are OpenCV's (x right, y down, z forward); [`WaymoCamera`] and [`Ego`] are
//!   forward-left-up. [`axes`] converts between them.
//! - [`QuatWxyz`] and [`QuatXyzw`] are distinct types; [`PoseEncoding`] is VGGT's `absT_quaR_FoV`.
//! - [`PixelConvention`] says whether pixel index `u` sits at coordinate `u` or `u + 0.5`.
//!
//! All geometry is `f64`: world coordinates of a driving log reach hundreds of metres, and the network's `f32`
//! tensors are converted at the tensor boundary, not here.

pub mod axes;
mod error;
pub mod frames;
pub mod horn;
mod interpolate;
mod intrinsics;
mod pose_encoding;
mod quaternion;
mod ray;
mod rigid;
mod unproject;

pub use error::GeomError;
pub use frames::{Camera, Ego, LogWorld, Sweep, WaymoCamera, World};
pub use interpolate::{PosedCamera, interpolate_intrinsics, interpolate_rigid};
pub use intrinsics::{ImageSize, PinholeIntrinsics, PixelConvention};
pub use pose_encoding::PoseEncoding;
pub use quaternion::{QuatWxyz, QuatXyzw, slerp};
pub use ray::ray_box_interval;
pub use rigid::{CameraFromWorld, EgoFromCamera, Rigid, WorldFromCamera, WorldFromEgo, WorldFromLogWorld};
pub use unproject::unproject_depth_map;

/// Re-exported so that callers use the same glam version as this crate.
pub use glam;
