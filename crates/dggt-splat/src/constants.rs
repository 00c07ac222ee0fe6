//! The rasteriser's numbers, defined once: the host reference, the CubeCL kernels and the culling of the scene
//! assembly (`dggt-scene`) all read them here, so that what the assembly drops is what the rasteriser would
//! skip. The values are gsplat's "classic" mode, which the release renders with.
//!
//! Where the host computes in `f64` and the kernels in `f32`, the `f32` form is derived from the one
//! definition.

/// Footprints whose alpha is below this are skipped; Gaussians whose opacity is below it are culled.
pub const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
/// A footprint's alpha is clamped to this, so no single Gaussian is fully opaque.
pub const MAX_ALPHA: f32 = 0.999;
/// Compositing stops before the transmittance would fall to this (the early stop).
pub const MIN_TRANSMITTANCE: f32 = 1e-4;
/// The expected depth divides by the accumulated alpha, floored at this.
pub const MIN_DEPTH_ALPHA: f32 = 1e-10;
/// The median depth is the depth of the footprint after which the transmittance is at or below this.
pub const MEDIAN_TRANSMITTANCE: f32 = 0.5;

/// How far beyond the field of view, as a fraction of the image's extent, the projection's `x/z` and `y/z` are
/// clamped before the Jacobian is formed (the guard band: `lim = (W - cx) / fx + GUARD_BAND · W / fx`).
pub const GUARD_BAND: f64 = 0.3;
/// [`GUARD_BAND`] as the kernels compute.
pub const GUARD_BAND_F32: f32 = GUARD_BAND as f32;

/// A footprint's screen box extends at most this many standard deviations from its centre per axis (less for
/// faint Gaussians: `min(MAX_BOX_SIGMAS, sqrt(2 ln(opacity / ALPHA_THRESHOLD)))`).
pub const MAX_BOX_SIGMAS: f64 = 3.33;
/// [`MAX_BOX_SIGMAS`] as the kernels compute.
pub const MAX_BOX_SIGMAS_F32: f32 = MAX_BOX_SIGMAS as f32;

/// Quaternions shorter than this are the identity rotation with zero gradient.
pub const QUAT_MIN_NORM: f64 = 1e-12;
/// [`QUAT_MIN_NORM`] as the kernels compute.
pub const QUAT_MIN_NORM_F32: f32 = QUAT_MIN_NORM as f32;

/// Gaussians at camera-space depth at or below this are culled (the default near plane).
pub const DEFAULT_NEAR_PLANE: f32 = 0.01;
/// Gaussians at camera-space depth at or beyond this are culled (the default far plane).
pub const DEFAULT_FAR_PLANE: f32 = 1e10;
/// Variance in pixels² added to every projected covariance's diagonal (the default low-pass `eps2d`).
pub const DEFAULT_EPS2D: f32 = 0.3;
/// Side of the square screen tiles (the default).
pub const DEFAULT_TILE_SIZE: u32 = 16;
/// The largest tile side: the GPU rasteriser composites a tile with one cube of `tile_size²` units, and 256
/// units is what every wgpu adapter offers (WebGPU's guaranteed workgroup size).
pub const MAX_TILE_SIZE: u32 = 16;
