//! What is rendered at a target time `t` from one forward pass:
//!
//! - the **static** union of every input view's Gaussians, opacity `o · (1 - sigmoid(dynamic logit))` faded by
//!   the lifespan to `t` ([`opacity_at`]);
//! - the **dynamic** Gaussians of the input view of the target's rig camera nearest to `t` (or of the two
//!   views bracketing `t`, cross-faded: [`DynamicBlend`]), opacity `o · sigmoid(dynamic logit)`, moved to `t`
//!   as [`DynamicMotion`] says: by their predicted velocity when the model has a motion head
//!   ([`PixelGaussians::with_motion`]), rigidly along their object's trajectory
//!   ([`PixelGaussians::with_instances`]), held where they were predicted otherwise;
//! - culled before the rasteriser sees them: a Gaussian whose opacity at `t` is below the rasteriser's own
//!   1/255 threshold, or whose conservative screen footprint misses the target image, is dropped.
//!
//! The culling rules only remove Gaussians the rasteriser would skip anyway (its alpha threshold and its
//! box of `MAX_BOX_SIGMAS` standard deviations), so a culled render equals the uncut one; [`AssemblySettings::exact`] turns
//! culling off to measure that.

use burn::tensor::{Int, Tensor, TensorData};
use dggt_geom::glam::{DMat3, DVec3};
use dggt_instances::{InstanceSettings, Instances, RigidMotion};
use dggt_model::host::host_f32;
use dggt_model::lifespan::{dynamic_opacity, opacity_at, static_opacity};
use dggt_splat::constants::{
    ALPHA_THRESHOLD, DEFAULT_EPS2D, DEFAULT_FAR_PLANE, DEFAULT_NEAR_PLANE, GUARD_BAND, MAX_BOX_SIGMAS_F32,
};
use dggt_splat::{GaussianTensors, OpacityTensor};
use rayon::prelude::*;

use crate::displacements::LearntStep;
use crate::error::SceneError;
use crate::motion::DynamicMotion;
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
    /// How those Gaussians move from their view's time to the target's.
    pub dynamic_motion: DynamicMotion,
    /// How the moving objects are found when [`DynamicMotion::Instances`] moves them.
    pub instances: InstanceSettings,
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
            dynamic_motion: DynamicMotion::Velocity,
            instances: InstanceSettings::default(),
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
    let (candidates, kept) = Candidates::choose(pixels, target, settings)?;
    Ok(AssembledGaussians { gaussians: candidates.gather(pixels, &kept), counts: kept.counts })
}

/// The world velocity (world units per unit of scene time, world axes) at the target's time of every Gaussian
/// [`assemble`] returns for `target`, in the same order: zero for the static union, the predicted velocity for a
/// dynamic Gaussian the velocities move (zero without them), the velocity of its moved point on its object's
/// trajectory for one an instance moves. Rasterised as colours, it gives each pixel's expected flow at any view.
pub fn assembled_velocities(
    pixels: &PixelGaussians,
    target: &TargetView,
    settings: &AssemblySettings,
) -> Result<Vec<[f32; 3]>, SceneError> {
    let (candidates, kept) = Candidates::choose(pixels, target, settings)?;
    Ok(candidates.velocities(pixels, &kept, target.time))
}

/// [`assemble`] and [`assembled_velocities`] at once, choosing the Gaussians once.
pub fn assemble_with_velocities(
    pixels: &PixelGaussians,
    target: &TargetView,
    settings: &AssemblySettings,
) -> Result<(AssembledGaussians, Vec<[f32; 3]>), SceneError> {
    let (candidates, kept) = Candidates::choose(pixels, target, settings)?;
    let velocities = candidates.velocities(pixels, &kept, target.time);
    Ok((AssembledGaussians { gaussians: candidates.gather(pixels, &kept), counts: kept.counts }, velocities))
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
    /// The candidates of `target` and the rows of them kept.
    fn choose(
        pixels: &PixelGaussians,
        target: &TargetView,
        settings: &AssemblySettings,
    ) -> Result<(Self, KeptRows), SceneError> {
        let candidates = Self::new(pixels, target, settings);
        let verdicts = candidates.verdicts(pixels, target, settings)?;
        let kept = KeptRows::of(&candidates.sources, &verdicts, pixels);
        tracing::debug!(
            time = target.time,
            candidates = kept.counts.candidates,
            transparent = kept.counts.transparent,
            off_screen = kept.counts.off_screen,
            kept = kept.counts.kept(),
            "assembled a target view"
        );
        Ok((candidates, kept))
    }

    /// The world velocity at time `at` of every kept row, in [`Candidates::gather`]'s order.
    fn velocities(&self, pixels: &PixelGaussians, kept: &KeptRows, at: f64) -> Vec<[f32; 3]> {
        let mut velocities = vec![[0.0; 3]; kept.statics.len()];
        for (source, rows) in self.sources.iter().zip(&kept.dynamics) {
            velocities.extend(rows.iter().map(|&row| source.velocity(pixels, row as usize, at)));
        }
        velocities
    }

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
        let instances = match settings.dynamic_motion {
            DynamicMotion::Instances => pixels.instances(),
            DynamicMotion::Velocity | DynamicMotion::Held | DynamicMotion::Learnt => None,
        };
        let sources: Vec<DynamicSource> = match &dynamic {
            Some(_) => dynamic_sources(&pixels.views, target.rig_camera, target.time, settings.dynamic_blend)
                .into_iter()
                .map(|(view, weight)| {
                    let from = pixels.views[view].time;
                    DynamicSource {
                        range: view * per_view..(view + 1) * per_view,
                        elapsed: (target.time - from) as f32,
                        weight: weight as f32,
                        motion: settings.dynamic_motion,
                        learnt: match (settings.dynamic_motion, pixels.learnt()) {
                            (DynamicMotion::Learnt, Some(flow)) => flow.step(view, from, target.time),
                            _ => None,
                        },
                        rigid: instances.map_or_else(Vec::new, |found| {
                            (0..found.len()).map(|k| found.motion(k, from, target.time)).collect()
                        }),
                    }
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
                    match source.motion(pixels, index) {
                        RowMotion::Held => mean,
                        RowMotion::Velocity(velocity, elapsed) => {
                            std::array::from_fn(|k| mean[k] + velocity[index][k] * elapsed)
                        }
                        RowMotion::Rigid(motion) => {
                            motion.apply(DVec3::from_array(mean.map(f64::from))).to_array().map(|v| v as f32)
                        }
                        RowMotion::Learnt(flow, step) => {
                            std::array::from_fn(|k| mean[k] + flow[index][k] * step.fraction)
                        }
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
        // The sources that kept any Gaussian, with their kept rows (grouped by how they move).
        let drawn: Vec<(&DynamicSource, &Vec<i64>)> =
            self.sources.iter().zip(&kept.dynamics).filter(|(_, index)| !index.is_empty()).collect();
        let moves = drawn.iter().any(|(source, rows)| {
            rows.iter().any(|&row| !matches!(source.motion(pixels, row as usize), RowMotion::Held))
        });
        let (means, quats_wxyz) = if moves {
            let statics = index_tensor(&kept.statics);
            let mut means = vec![pixels.means.clone().select(0, statics.clone())];
            let mut quats = vec![pixels.quats_wxyz.clone().select(0, statics)];
            for &(source, rows) in &drawn {
                for run in rows.chunk_by(|a, b| source.group(pixels, *a as usize) == source.group(pixels, *b as usize))
                {
                    let index = index_tensor(run);
                    let (run_means, run_quats) = (
                        pixels.means.clone().select(0, index.clone()),
                        pixels.quats_wxyz.clone().select(0, index.clone()),
                    );
                    let (moved, turned) = match source.motion(pixels, run[0] as usize) {
                        RowMotion::Held => (run_means, run_quats),
                        RowMotion::Velocity(..) => {
                            let velocity = pixels.velocity.as_ref().expect("a velocity motion has velocities");
                            (run_means + velocity.clone().select(0, index).mul_scalar(source.elapsed), run_quats)
                        }
                        RowMotion::Rigid(motion) => rigidly_moved(run_means, run_quats, motion),
                        RowMotion::Learnt(_, step) => {
                            let flow = pixels.learnt().expect("a learnt motion has a learnt flow");
                            let displacement = flow.tensor(step.towards).clone().select(0, index);
                            (run_means + displacement.mul_scalar(step.fraction), run_quats)
                        }
                    };
                    means.push(moved);
                    quats.push(turned);
                }
            }
            (Tensor::cat(means, 0), Tensor::cat(quats, 0))
        } else {
            (pick(&pixels.means), pick(&pixels.quats_wxyz))
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
            quats_wxyz,
            scales: pick(&pixels.scales),
            opacities: OpacityTensor::Shared(Tensor::cat(opacities, 0)),
            colors: pick(&pixels.colors),
        }
    }
}

/// Means `[n, 3]` and rotations `[n, 4]` (`w x y z`) moved by `motion`: `R m + t` and `r ⊗ q` (`r` the
/// motion's rotation), as products with constant matrices so that gradients pass through.
fn rigidly_moved(means: Tensor<2>, quats_wxyz: Tensor<2>, motion: &RigidMotion) -> (Tensor<2>, Tensor<2>) {
    let device = means.device();
    let matrix = DMat3::from_quat(motion.rotation);
    // Row vectors times Rᵀ: element (i, j) = R(j, i).
    let rotation: Vec<f32> = (0..3).flat_map(|i| (0..3).map(move |j| matrix.col(i)[j] as f32)).collect();
    let rotation = Tensor::<2>::from_data(TensorData::new(rotation, [3, 3]), &device);
    let translation = motion.translation.to_array().map(|v| v as f32);
    let translation = Tensor::<2>::from_data(TensorData::new(translation.to_vec(), [1, 3]), &device);
    // r ⊗ q as a row vector q times L: element (i, j) is the weight of q_i in component j of the product.
    let r = motion.rotation;
    let (w, x, y, z) = (r.w as f32, r.x as f32, r.y as f32, r.z as f32);
    let left = [w, x, y, z, -x, w, z, -y, -y, -z, w, x, -z, y, -x, w];
    let left = Tensor::<2>::from_data(TensorData::new(left.to_vec(), [4, 4]), &device);
    (means.matmul(rotation) + translation, quats_wxyz.matmul(left))
}

impl KeptRows {
    fn of(sources: &[DynamicSource], verdicts: &Verdicts, pixels: &PixelGaussians) -> Self {
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
        // Each source's rows grouped by how they move (stable: pixel order within a group).
        let dynamics: Vec<Vec<i64>> = sources
            .iter()
            .zip(dynamics)
            .map(|(source, verdicts)| {
                let mut rows = kept(verdicts, source.range.start);
                if source.rigid.iter().any(|motion| *motion != RigidMotion::IDENTITY) {
                    rows.sort_by_key(|&row| source.group(pixels, row as usize));
                }
                rows
            })
            .collect();
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
    /// Whether the predicted velocities move the rows no instance moves ([`DynamicMotion::Held`] holds them).
    motion: DynamicMotion,
    /// How far along their learnt displacement the view's rows are; `None` unless the learnt flow moves them.
    learnt: Option<LearntStep>,
    /// Per instance, its motion from the view's time to the target's; empty unless instances move the
    /// Gaussians.
    rigid: Vec<RigidMotion>,
}

/// How one dynamic row reaches the target time.
enum RowMotion<'a> {
    Held,
    /// By the host velocities, over the elapsed scene time.
    Velocity(&'a [[f32; 3]], f32),
    Rigid(&'a RigidMotion),
    /// By a fraction of the host learnt displacements.
    Learnt(&'a [[f32; 3]], LearntStep),
}

impl DynamicSource {
    /// The instance row `row` belongs to when instances move it, else [`Instances::NONE`].
    fn group(&self, pixels: &PixelGaussians, row: usize) -> u32 {
        match pixels.instances() {
            Some(instances) if !self.rigid.is_empty() => {
                let per_view = pixels.per_view();
                instances.labels(row / per_view)[row % per_view]
            }
            _ => Instances::NONE,
        }
    }

    /// The host velocities that move the rows no instance moves, unless this source holds them.
    fn host_velocity<'a>(&self, pixels: &'a PixelGaussians) -> Option<&'a [[f32; 3]]> {
        match self.motion {
            DynamicMotion::Held | DynamicMotion::Learnt => None,
            DynamicMotion::Velocity | DynamicMotion::Instances => pixels.host_velocity.as_deref(),
        }
    }

    /// Row `row`'s world velocity at time `at` under this source's motion (see [`assembled_velocities`]).
    fn velocity(&self, pixels: &PixelGaussians, row: usize, at: f64) -> [f32; 3] {
        match (self.group(pixels, row), pixels.instances()) {
            (Instances::NONE, _) | (_, None) => match self.motion(pixels, row) {
                RowMotion::Learnt(flow, step) => flow[row].map(|v| v * step.rate),
                _ => self.host_velocity(pixels).map_or([0.0; 3], |velocity| velocity[row]),
            },
            (instance, Some(found)) => {
                let instance = instance as usize;
                let moved = self.rigid[instance].apply(DVec3::from_array(pixels.host_means[row].map(f64::from)));
                found.point_velocity(instance, at, moved).to_array().map(|v| v as f32)
            }
        }
    }

    fn motion<'a>(&'a self, pixels: &'a PixelGaussians, row: usize) -> RowMotion<'a> {
        match self.group(pixels, row) {
            Instances::NONE => match (self.learnt, pixels.learnt(), self.host_velocity(pixels)) {
                (Some(step), Some(flow), _) => RowMotion::Learnt(flow.host(step.towards), step),
                (_, _, Some(velocity)) if self.elapsed != 0.0 => RowMotion::Velocity(velocity, self.elapsed),
                _ => RowMotion::Held,
            },
            instance => match &self.rigid[instance as usize] {
                motion if *motion == RigidMotion::IDENTITY => RowMotion::Held,
                motion => RowMotion::Rigid(motion),
            },
        }
    }
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
