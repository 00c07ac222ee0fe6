//! The kernel arguments that several launches share, each passed as one argument and built on the host in one
//! place (`Layout::grid`, `blend_inputs`), so that every launch hands the kernels the same values in the same
//! way.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// The sizes of one call as the kernels read them: the Gaussians, the views, the image and its tile grid.
/// Runtime values, so one compiled kernel serves every size.
#[derive(CubeType, CubeLaunch, Clone, Copy)]
#[expand(derive(Clone, Copy))]
pub struct Grid {
    /// Gaussians `N`.
    pub count: u32,
    /// Views `V` of the call (all of them, not those of a batch).
    pub views: u32,
    /// `1` where the opacities are per view (`[V, N]`), `0` where the views share them (`[N]`).
    pub per_view: u32,
    /// Image width `W` in pixels.
    pub width: u32,
    /// Image height `H` in pixels.
    pub height: u32,
    /// Edge of a square tile in pixels.
    pub tile_size: u32,
    /// Tiles a row, `⌈W / tile_size⌉`.
    pub tiles_x: u32,
    /// Tiles a column, `⌈H / tile_size⌉`.
    pub tiles_y: u32,
}

/// What both compositing passes read for a batch of views: its sorted tile lists, the footprints of every
/// (view, Gaussian) pair and the Gaussians' opacities and colours, and the background. Eight storage buffers,
/// as when passed one by one.
#[derive(CubeType, CubeLaunch)]
pub struct BlendInputs {
    /// The batch's sorted Gaussian ids (`ListBatch::ids`).
    pub ids: OwnedTensor<u32>,
    /// The batch's list ranges (`ListBatch::ranges`).
    pub ranges: OwnedTensor<u32>,
    /// `[V, N, 2]`.
    pub means2d: OwnedTensor<f32>,
    /// `[V, N, 3]`.
    pub conics: OwnedTensor<f32>,
    /// `[V, N]`.
    pub depths: OwnedTensor<f32>,
    /// `[N]` or `[V, N]` (see [`Grid::per_view`]).
    pub opacities: OwnedTensor<f32>,
    /// `[N, K]`.
    pub colors: OwnedTensor<f32>,
    /// `[K]`.
    pub background: OwnedTensor<f32>,
}
