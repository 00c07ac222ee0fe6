//! 4D scene assembly: from one forward pass of the network to the Gaussians rendered at any time.
//!
//! The data flow, one module per step:
//!
//! 1. [`timeline`]: the input views' rig cameras and scene times; target cameras interpolated from them.
//! 2. [`pixels`]: the per-pixel Gaussians of every input view, means unprojected from the predicted depth;
//!    [`learnt`]: the flow head run on their dynamic pixels, its displacements to the neighbouring inputs kept
//!    as [`displacements`];
//!    [`reach`]: how far the head would have to look to find where its queries truly go (a diagnostic).
//! 3. [`motion`]: how the dynamic Gaussians move between the inputs (the setting, its demands on a model,
//!    what it needs found first); [`assemble`]: the static union faded by the lifespan to the target time, the
//!    dynamic Gaussians of the view(s) nearest in time, and culling of what the rasteriser would skip.
//! 4. [`compose`]: rasterising the assembled Gaussians and compositing them over the sky;
//! 5. [`scene4d`]: all of it as one value, [`Scene4d`], that renders any target view at any time;
//! 6. [`saved`]: a [`Scene4d`] in one file and back, so that it renders (and is edited) without the network.
//!
//! Conventions: cameras are [`PosedCamera`](dggt_geom::PosedCamera)s (world-from-camera poses, OpenCV axes);
//! quaternions `w x y z`; scales linear; opacities in `[0, 1]`; the world is the first input camera's frame
//! when cameras are predicted.

pub mod assemble;
pub mod compose;
pub mod displacements;
mod error;
pub mod learnt;
pub mod motion;
pub mod pixels;
pub mod reach;
pub mod saved;
pub mod scene4d;
pub mod timeline;

pub use assemble::{
    AssembledGaussians, AssemblyCounts, AssemblySettings, HiddenSky, MIN_OPACITY, assemble, assemble_with_velocities,
    assembled_velocities,
};
pub use compose::{
    ViewRender, camera_tensors, composite, render_assembled, render_depth, render_flow, render_target, render_targets,
    sky_splats,
};
pub use dggt_instances::{InstanceSettings, Instances};
pub use dggt_splat::DepthStatistic;
pub use displacements::{LearntFlow, LearntVelocity};
pub use error::SceneError;
pub use motion::{DynamicMotion, FlowHeadMismatch};
pub use pixels::{Axes, MeansGradient, PixelGaussians};
pub use reach::FlowReach;
pub use saved::{SCENE_FILE, load_scene, save_scene, scene_file};
pub use scene4d::Scene4d;
pub use timeline::{
    DynamicBlend, InputView, TargetView, Timeline, dynamic_sources, interpolate_camera, nearest_in_time, nearest_view,
};
