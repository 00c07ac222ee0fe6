//! The learnt scene-flow head of DGGT: for two adjacent input times `ta < tb`, the 3D displacement
//! `F(ta, tb)` of each dynamic query pixel of `ta` to time `tb`. A dynamic Gaussian drawn at an in-between time
//! `ti` sits at `mu_a + w F(ta, tb)` with `w = (ti - ta) / (tb - ta)`.
//!
//! The data flow, one module per step:
//!
//! 1. [`sample`]: multi-scale image features read at the query and target pixels (bilinear, pixel centres);
//! 2. [`cloud`]: one time's points (the Gaussian means) with their features, checked, as a [`FrameCloud`];
//! 3. [`neighbours`]: the k nearest target points of each moved query (an R*-tree on the host, brute force on a
//!    CubeCL device);
//! 4. [`scale`]: the cloud's sampling spacing, the unit the head measures offsets in;
//! 5. [`head`]: [`FlowHead`], the transformer that refines each query's displacement by attention over its
//!    target neighbourhood, built from a [`FlowHeadConfig`] ([`config`]);
//! 6. [`attention`]: the per-neighbour sums of that attention, a fused op with a hand-written backward (on the
//!    host, and as CubeCL kernels), or burn's tensor operations elsewhere.
//!
//! Conventions: points and displacements in the reconstruction's world axes and units (whatever scale the network
//! predicted); one point per row (`[N, 3]`, `x y z`), features row-aligned with the points (`[N, C]`); the
//! displacement of a query row goes from its point at the query's time `ta` to where that point is at the target's
//! time `tb`.

pub mod attention;
pub mod cloud;
pub mod config;
pub mod head;
mod mlp;
pub mod neighbours;
pub mod sample;
pub mod scale;

pub use cloud::{CloudRole, FlowError, FrameCloud};
pub use config::{ConfigError, FlowHeadConfig, FlowHeadShape, HeadInputs};
pub use dggt_geom::ImageSize;
pub use head::{FlowHead, PreparedCloud};
pub use sample::{PixelIndex, SampleError, sample_features};
