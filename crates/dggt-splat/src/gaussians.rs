//! The Gaussians to render, as borrowed flat `f32` buffers (structure of arrays, row-major).
//!
//! Borrowing lets a tensor backend hand its storage over without a copy, and the flat layout is the one a GPU
//! kernel reads. Opacities are either one value per Gaussian or one per rendered view: DGGT's lifespan fades
//! every Gaussian with the time of the view being rendered, so a batch of views needs `[V, N]` opacities.

use crate::error::{SplatError, expect_len};

/// Opacities shared by all views (`[N]`) or given per view (`[V, N]`, row `v` for view `v`).
///
/// The same type carries opacity gradients: their shape follows the input's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Opacities<T> {
    /// `[N]`: every view sees the same opacity.
    Shared(T),
    /// `[V, N]`: view `v` uses row `v`.
    PerView(T),
}

impl<T: AsRef<[f32]>> Opacities<T> {
    /// The flat values, whichever the shape.
    pub fn values(&self) -> &[f32] {
        match self {
            Opacities::Shared(v) | Opacities::PerView(v) => v.as_ref(),
        }
    }

    /// Borrows the values, keeping the shape.
    pub fn as_slices(&self) -> Opacities<&[f32]> {
        match self {
            Opacities::Shared(v) => Opacities::Shared(v.as_ref()),
            Opacities::PerView(v) => Opacities::PerView(v.as_ref()),
        }
    }

    /// The opacity of Gaussian `index` in view `view`.
    pub(crate) fn get(&self, view: usize, index: usize, count: usize) -> f32 {
        match self {
            Opacities::Shared(v) => v.as_ref()[index],
            Opacities::PerView(v) => v.as_ref()[view * count + index],
        }
    }
}

/// N Gaussians in world space.
///
/// | buffer | shape | meaning |
/// |---|---|---|
/// | `means` | `[N, 3]` | centres, world coordinates |
/// | `quats` | `[N, 4]` | rotations, scalar first (`w x y z`), any non-zero norm (normalised inside) |
/// | `scales` | `[N, 3]` | standard deviations along the rotated axes (linear, not log) |
/// | `opacities` | `[N]` or `[V, N]` | in `[0, 1]` |
/// | `colors` | `[N, K]` | any `K >= 1` channels composited alike (RGB plus e.g. a dynamic probability) |
#[derive(Debug, Clone, Copy)]
pub struct Gaussians<'a> {
    means: &'a [f32],
    quats: &'a [f32],
    scales: &'a [f32],
    opacities: Opacities<&'a [f32]>,
    colors: &'a [f32],
    channels: usize,
    count: usize,
}

impl<'a> Gaussians<'a> {
    /// Checks the buffer lengths against `N = means.len() / 3` and `channels` (`K`). Per-view opacities are
    /// checked against the number of views when rendering.
    pub fn new(
        means: &'a [f32],
        quats: &'a [f32],
        scales: &'a [f32],
        opacities: Opacities<&'a [f32]>,
        colors: &'a [f32],
        channels: usize,
    ) -> Result<Self, SplatError> {
        if channels == 0 {
            return Err(SplatError::Shape { tensor: "colors", expected: "at least one channel".into(), actual: 0 });
        }
        if !means.len().is_multiple_of(3) {
            return Err(SplatError::Shape {
                tensor: "means",
                expected: "a multiple of 3 ([N, 3])".into(),
                actual: means.len(),
            });
        }
        let count = means.len() / 3;
        if count > u32::MAX as usize {
            return Err(SplatError::Shape {
                tensor: "means",
                expected: format!("at most {} Gaussians (tile lists index them with u32)", u32::MAX),
                actual: means.len(),
            });
        }
        expect_len("quats", quats, count, 4, "[N, 4] wxyz")?;
        expect_len("scales", scales, count, 3, "[N, 3]")?;
        expect_len("colors", colors, count, channels, "[N, K]")?;
        if let Opacities::Shared(values) = opacities {
            expect_len("opacities", values, count, 1, "[N]")?;
        }
        Ok(Self { means, quats, scales, opacities, colors, channels, count })
    }

    /// Number of Gaussians `N`.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Number of colour channels `K`.
    pub fn channels(&self) -> usize {
        self.channels
    }

    pub fn means(&self) -> &'a [f32] {
        self.means
    }

    pub fn quats(&self) -> &'a [f32] {
        self.quats
    }

    pub fn scales(&self) -> &'a [f32] {
        self.scales
    }

    pub fn opacities(&self) -> Opacities<&'a [f32]> {
        self.opacities
    }

    pub fn colors(&self) -> &'a [f32] {
        self.colors
    }

    /// Checks per-view opacities against the number of views.
    pub(crate) fn check_views(&self, views: usize) -> Result<(), SplatError> {
        if let Opacities::PerView(values) = self.opacities {
            expect_len("opacities", values, views, self.count, "[V, N] per-view")?;
        }
        Ok(())
    }

    pub(crate) fn mean(&self, i: usize) -> [f32; 3] {
        [self.means[3 * i], self.means[3 * i + 1], self.means[3 * i + 2]]
    }

    pub(crate) fn quat(&self, i: usize) -> [f32; 4] {
        [self.quats[4 * i], self.quats[4 * i + 1], self.quats[4 * i + 2], self.quats[4 * i + 3]]
    }

    pub(crate) fn scale(&self, i: usize) -> [f32; 3] {
        [self.scales[3 * i], self.scales[3 * i + 1], self.scales[3 * i + 2]]
    }

    pub(crate) fn color(&self, i: usize) -> &'a [f32] {
        &self.colors[i * self.channels..(i + 1) * self.channels]
    }

    pub(crate) fn opacity(&self, view: usize, i: usize) -> f32 {
        self.opacities.get(view, i, self.count)
    }

    /// Whether the view-independent parameters of Gaussian `i` (mean, rotation, scale, colour) are all finite.
    pub(crate) fn is_finite(&self, i: usize) -> bool {
        self.mean(i).iter().chain(&self.quat(i)).chain(&self.scale(i)).chain(self.color(i)).all(|v| v.is_finite())
    }
}
