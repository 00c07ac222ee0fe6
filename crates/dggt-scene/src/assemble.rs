//! What is rendered at a target time `t` from one forward pass:
//!
//! - the **static** union of every input view's Gaussians, opacity `o · (1 - sigmoid(dynamic logit))` faded by
//!   the lifespan to `t` ([`opacity_at`]);
//! - the **dynamic** Gaussians of the input view of the target's rig camera nearest to `t` (or of the two
//!   views bracketing `t`, cross-faded: [`DynamicBlend`]), opacity `o · sigmoid(dynamic logit)`, moved to `t`
//!   by their predicted velocity when the model has a motion head ([`PixelGaussians::with_motion`]), held where
//!   they were predicted otherwise;
//! - culled before the rasteriser sees them: a Gaussian whose opacity at `t` is below the rasteriser's own
//!   1/255 threshold, or whose conservative screen footprint misses the target image, is dropped.
//!
//! The culling rules only remove Gaussians the rasteriser would skip anyway (its alpha threshold and its
//! box of `MAX_BOX_SIGMAS` standard deviations), so a culled render equals the uncut one; [`AssemblySettings::exact`] turns
//! culling off to measure that.

use burn::tensor::{Int, Tensor, TensorData};
use dggt_model::host::host_f32;
use dggt_model::lifespan::{dynamic_opacity, opacity_at, static_opacity};
use dggt_splat::constants::{
    ALPHA_THRESHOLD, DEFAULT_EPS2D, DEFAULT_FAR_PLANE, DEFAULT_NEAR_PLANE, GUARD_BAND, MAX_BOX_SIGMAS_F32,
};
use dggt_splat::{GaussianTensors, OpacityTensor};
use rayon::prelude::*;

use crate::error::SceneError;
use crate::pixels::PixelGaussians;
use crate::timeline::{DynamicBlend, TargetView, dynamic_sources};

/// The rasteriser's alpha threshold: Gaussians below it never contribute.
pub const MIN_OPACITY: f32 = ALPHA_THRESHOLD;

/// How Gaussians are chosen for a target view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssemblySettings {
    /// Drop Gaussians whose opacity at the target time is below this.
    pub min_opacity: f32,
    /// Drop Gaussians whose footprint misses the image or that lie outside `[near_plane, far_plane]`.
    pub cull_off_screen: bool,
    /// Camera-space depth below which a Gaussian is behind the camera (the rasteriser's near plane).
    pub near_plane: f32,
    /// Camera-space depth beyond which Gaussians are not drawn (the rasteriser's far plane). A finite one
    /// bounds a scene: a Gaussian pushed beyond it gets no gradient, so depths without supervision cannot
    /// grow without limit.
    pub far_plane: f32,
    /// Which input views lend their dynamic Gaussians to the target time.
    pub dynamic_blend: DynamicBlend,
    /// Variance in pixels² added to each projected covariance's diagonal (the rasteriser's `eps2d`; 0.3 in the
    /// release): a low-pass floor under every footprint.
    pub eps2d: f32,
    /// Whether the sky behind a view that the foreground covers is rendered at all.
    pub hidden_sky: HiddenSky,
}

/// Whether the sky is rendered behind a view whose foreground covers it everywhere.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum HiddenSky {
    /// Always rendered: the exact composite.
    #[default]
    Render,
    /// Not rendered when the foreground's transmittance `1 - alpha` is below `tolerance` at every pixel:
    /// each colour then differs from the exact composite by less than `tolerance` times the sky's colour.
    Skip { tolerance: f32 },
}

impl HiddenSky {
    /// Skipped below one 8-bit level: the images change by less than `1/255` of the sky's colour.
    pub const BELOW_ONE_LEVEL: Self = Self::Skip { tolerance: 1.0 / 255.0 };
}

impl Default for AssemblySettings {
    fn default() -> Self {
        Self {
            min_opacity: MIN_OPACITY,
            cull_off_screen: true,
            near_plane: DEFAULT_NEAR_PLANE,
            far_plane: DEFAULT_FAR_PLANE,
            dynamic_blend: DynamicBlend::Nearest,
            eps2d: DEFAULT_EPS2D,
            hidden_sky: HiddenSky::Render,
        }
    }
}

impl AssemblySettings {
    /// Every Gaussian reaches the rasteriser.
    pub fn exact() -> Self {
        Self { min_opacity: 0.0, cull_off_screen: false, ..Self::default() }
    }
}

/// How many Gaussians each stage kept or dropped for one target view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AssemblyCounts {
    /// Static and dynamic candidates before culling.
    pub candidates: usize,
    /// Dropped: opacity at the target time below the threshold (faded by the lifespan, or transparent).
    pub transparent: usize,
    /// Dropped: footprint outside the image or behind the camera.
    pub off_screen: usize,
    pub static_kept: usize,
    pub dynamic_kept: usize,
}

impl AssemblyCounts {
    pub fn kept(&self) -> usize {
        self.static_kept + self.dynamic_kept
    }
}

/// The Gaussians of one target view, ready for the rasteriser.
#[derive(Debug, Clone)]
pub struct AssembledGaussians {
    pub gaussians: GaussianTensors,
    pub counts: AssemblyCounts,
}

/// Assembles the Gaussians visible at `target`.
pub fn assemble(
    pixels: &PixelGaussians,
    target: &TargetView,
    settings: &AssemblySettings,
) -> Result<AssembledGaussians, SceneError> {
    let candidates = Candidates::new(pixels, target, settings);
    let verdicts = candidates.verdicts(pixels, target, settings)?;
    let kept = KeptRows::of(&candidates.sources, &verdicts);
    tracing::debug!(
        time = target.time,
        candidates = kept.counts.candidates,
        transparent = kept.counts.transparent,
        off_screen = kept.counts.off_screen,
        kept = kept.counts.kept(),
        "assembled a target view"
    );
    Ok(AssembledGaussians { gaussians: candidates.gather(pixels, &kept), counts: kept.counts })
}

/// Every Gaussian as a static candidate, faded to the target time, and the dynamic ones of the source views.
struct Candidates {
    /// `[M]` static opacities faded by the lifespan to the target time.
    faded: Tensor<1>,
    /// `[M]` dynamic opacities; `None` without a dynamic head.
    dynamic: Option<Tensor<1>>,
    sources: Vec<DynamicSource>,
}

/// The culling verdict of every static candidate, and of every source view's dynamic candidates.
struct Verdicts {
    statics: Vec<Verdict>,
    dynamics: Vec<Vec<Verdict>>,
}

/// The rows kept, static then per source view, with the counts.
struct KeptRows {
    statics: Vec<i64>,
    dynamics: Vec<Vec<i64>>,
    counts: AssemblyCounts,
}

impl Candidates {
    fn new(pixels: &PixelGaussians, target: &TargetView, settings: &AssemblySettings) -> Self {
        let per_view = pixels.per_view();
        let (static_opacity_all, dynamic) = match &pixels.dynamic_logit {
            Some(logit) => (
                static_opacity(pixels.opacity.clone(), logit.clone()),
                Some(dynamic_opacity(pixels.opacity.clone(), logit.clone())),
            ),
            None => (pixels.opacity.clone(), None),
        };
        let faded = opacity_at(static_opacity_all, pixels.lifespan.clone(), pixels.source_time.clone(), target.time);
        // The dynamic ones of the source views, moved over their `elapsed` scene time and weighted.
        let sources: Vec<DynamicSource> = match &dynamic {
            Some(_) => dynamic_sources(&pixels.views, target.rig_camera, target.time, settings.dynamic_blend)
                .into_iter()
                .map(|(view, weight)| DynamicSource {
                    range: view * per_view..(view + 1) * per_view,
                    elapsed: (target.time - pixels.views[view].time) as f32,
                    weight: weight as f32,
                })
                .collect(),
            None => Vec::new(),
        };
        Self { faded, dynamic, sources }
    }

    /// Which candidates the rasteriser would draw: opaque enough at the target time, and on screen.
    fn verdicts(
        &self,
        pixels: &PixelGaussians,
        target: &TargetView,
        settings: &AssemblySettings,
    ) -> Result<Verdicts, SceneError> {
        let static_values = host_f32(self.faded.clone(), "static opacity")?;
        let footprint = Footprint::new(target, pixels.size, settings);
        let keep = |index: usize, mean: [f32; 3], opacity: f32| -> Verdict {
            if !(opacity >= settings.min_opacity) {
                Verdict::Transparent
            } else if settings.cull_off_screen && !footprint.on_screen(mean, pixels.host_max_scale[index]) {
                Verdict::OffScreen
            } else {
                Verdict::Keep
            }
        };
        let statics = static_values.par_iter().enumerate().map(|(i, &o)| keep(i, pixels.host_means[i], o)).collect();
        let mut dynamics = Vec::with_capacity(self.sources.len());
        if let Some(opacity) = &self.dynamic {
            for source in &self.sources {
                let values =
                    host_f32(opacity.clone().narrow(0, source.range.start, source.range.len()), "dynamic opacity")?;
                let displaced = |index: usize| -> [f32; 3] {
                    let mean = pixels.host_means[index];
                    match &pixels.host_velocity {
                        Some(velocity) => std::array::from_fn(|k| mean[k] + velocity[index][k] * source.elapsed),
                        None => mean,
                    }
                };
                let verdicts: Vec<Verdict> = values
                    .par_iter()
                    .enumerate()
                    .map(|(i, &o)| {
                        let index = source.range.start + i;
                        keep(index, displaced(index), o * source.weight)
                    })
                    .collect();
                dynamics.push(verdicts);
            }
        }
        Ok(Verdicts { statics, dynamics })
    }

    /// The kept rows' tensors, the dynamic ones moved and weighted.
    fn gather(&self, pixels: &PixelGaussians, kept: &KeptRows) -> GaussianTensors {
        let device = pixels.opacity.device();
        let index_tensor =
            |index: &[i64]| Tensor::<1, Int>::from_data(TensorData::new(index.to_vec(), [index.len()]), &device);
        let all: Vec<i64> = kept.statics.iter().chain(kept.dynamics.iter().flatten()).copied().collect();
        let all = index_tensor(&all);
        let pick = |tensor: &Tensor<2>| tensor.clone().select(0, all.clone());
        // The sources that kept any Gaussian, with their kept rows.
        let drawn: Vec<(&DynamicSource, &Vec<i64>)> =
            self.sources.iter().zip(&kept.dynamics).filter(|(_, index)| !index.is_empty()).collect();
        let means = match &pixels.velocity {
            Some(velocity) if drawn.iter().any(|(source, _)| source.elapsed != 0.0) => {
                let mut parts = vec![pixels.means.clone().select(0, index_tensor(&kept.statics))];
                for &(source, index) in &drawn {
                    let index = index_tensor(index);
                    parts.push(
                        pixels.means.clone().select(0, index.clone())
                            + velocity.clone().select(0, index).mul_scalar(source.elapsed),
                    );
                }
                Tensor::cat(parts, 0)
            }
            _ => pick(&pixels.means),
        };
        let mut opacities = vec![self.faded.clone().select(0, index_tensor(&kept.statics))];
        if let Some(dynamic) = &self.dynamic {
            for &(source, index) in &drawn {
                let picked = dynamic.clone().select(0, index_tensor(index));
                opacities.push(if source.weight == 1.0 { picked } else { picked.mul_scalar(source.weight) });
            }
        }
        GaussianTensors {
            means,
            quats_wxyz: pick(&pixels.quats_wxyz),
            scales: pick(&pixels.scales),
            opacities: OpacityTensor::Shared(Tensor::cat(opacities, 0)),
            colors: pick(&pixels.colors),
        }
    }
}

impl KeptRows {
    fn of(sources: &[DynamicSource], verdicts: &Verdicts) -> Self {
        let Verdicts { statics, dynamics } = verdicts;
        let mut counts = AssemblyCounts {
            candidates: statics.len() + dynamics.iter().map(Vec::len).sum::<usize>(),
            ..Default::default()
        };
        for verdict in statics.iter().chain(dynamics.iter().flatten()) {
            match verdict {
                Verdict::Transparent => counts.transparent += 1,
                Verdict::OffScreen => counts.off_screen += 1,
                Verdict::Keep => {}
            }
        }
        let kept = |verdicts: &[Verdict], offset: usize| -> Vec<i64> {
            let keep = |(i, v): (usize, &Verdict)| (*v == Verdict::Keep).then_some((offset + i) as i64);
            verdicts.iter().enumerate().filter_map(keep).collect()
        };
        let statics = kept(statics, 0);
        let dynamics: Vec<Vec<i64>> =
            sources.iter().zip(dynamics).map(|(source, verdicts)| kept(verdicts, source.range.start)).collect();
        counts.static_kept = statics.len();
        counts.dynamic_kept = dynamics.iter().map(Vec::len).sum();
        Self { statics, dynamics, counts }
    }
}

/// One input view lending its dynamic Gaussians to the target.
struct DynamicSource {
    /// The view's rows of the per-pixel Gaussians.
    range: std::ops::Range<usize>,
    /// Scene time from the view to the target, over which predicted velocities move its Gaussians.
    elapsed: f32,
    /// Multiplies the view's dynamic opacities.
    weight: f32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Verdict {
    Keep,
    Transparent,
    OffScreen,
}

/// A conservative test of whether a Gaussian can touch the image: its centre in front of the near plane and
/// within its screen radius of the image. The radius bounds the rasteriser's box (`MAX_BOX_SIGMAS` standard
/// deviations per axis, rounded up): that many times the largest scale projected at the centre's depth with the
/// larger focal length, plus as many of the `eps2d` blur (`sqrt(a + b) <= sqrt(a) + sqrt(b)`) and a pixel.
struct Footprint {
    rotation: [[f32; 3]; 3],
    translation: [f32; 3],
    focal: [f32; 2],
    centre: [f32; 2],
    /// Bounds the norm of a row of the projection's Jacobian times depth: the larger focal length times
    /// `sqrt(1 + lim_x² + lim_y²)`, with `lim` bounding the rasteriser's clamp of `x/z`, `y/z` (its guard band).
    radius_gain: f32,
    width: f32,
    height: f32,
    /// Pixels added to every radius: the box sigmas of the rasteriser's `eps2d` blur, plus one for its
    /// rounding up.
    blur_margin: f32,
    near: f32,
    far: f32,
}

impl Footprint {
    fn new(target: &TargetView, size: dggt_geom::ImageSize, settings: &AssemblySettings) -> Self {
        let camera_from_world = target.camera.world_from_camera.inverse();
        let rows = camera_from_world.to_rows();
        let k = &target.camera.intrinsics;
        Self {
            rotation: std::array::from_fn(|r| std::array::from_fn(|c| rows[r][c] as f32)),
            translation: std::array::from_fn(|r| rows[r][3] as f32),
            focal: [k.fx as f32, k.fy as f32],
            centre: [k.cx as f32, k.cy as f32],
            radius_gain: {
                let (w, h) = (size.width as f64, size.height as f64);
                let lim_x = (w - k.cx).max(k.cx) / k.fx + GUARD_BAND * w / k.fx;
                let lim_y = (h - k.cy).max(k.cy) / k.fy + GUARD_BAND * h / k.fy;
                (k.fx.max(k.fy) * (1.0 + lim_x * lim_x + lim_y * lim_y).sqrt()) as f32
            },
            width: size.width as f32,
            height: size.height as f32,
            blur_margin: MAX_BOX_SIGMAS_F32 * settings.eps2d.max(0.0).sqrt() + 1.0,
            near: settings.near_plane,
            far: settings.far_plane,
        }
    }

    fn on_screen(&self, mean: [f32; 3], max_scale: f32) -> bool {
        let p: [f32; 3] = std::array::from_fn(|r| {
            self.rotation[r][0] * mean[0]
                + self.rotation[r][1] * mean[1]
                + self.rotation[r][2] * mean[2]
                + self.translation[r]
        });
        if !(p[2] > self.near && p[2] < self.far) {
            return false;
        }
        let u = self.focal[0] * p[0] / p[2] + self.centre[0];
        let v = self.focal[1] * p[1] / p[2] + self.centre[1];
        let radius = MAX_BOX_SIGMAS_F32 * max_scale * self.radius_gain / p[2] + self.blur_margin;
        if !(u.is_finite() && v.is_finite() && radius.is_finite()) {
            // Left to the rasteriser, which sanitises and counts such Gaussians.
            return true;
        }
        u + radius >= 0.0 && u - radius <= self.width && v + radius >= 0.0 && v - radius <= self.height
    }
}
