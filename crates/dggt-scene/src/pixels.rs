//! The per-pixel Gaussians of one forward pass, flattened view-major (Gaussian `v · H · W + row · W + col` is
//! pixel `(col, row)` of input view `v`), with the camera and time of the view each came from.
//!
//! Means are the predicted depth unprojected at the pixel coordinates the model was trained with (integer ones
//! for the release's weights, pixel centres for models trained here; [`PixelConvention`]) with the views' cameras: `X_world = c + d · Rᵀ K⁻¹ (u, v, 1)`, `c` the camera centre. The cameras are constants; the
//! depth carries gradients unless [`MeansGradient::Detached`] (the release detaches the means). Host copies of
//! the means and of each Gaussian's largest scale are kept for culling.

use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::DVec3;
use dggt_geom::{ImageSize, PixelConvention};
use dggt_instances::{InstanceSettings, Instances, ViewPoints, find_instances};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_model::host::host_f32;

use crate::error::SceneError;
use crate::timeline::InputView;

/// Whether gradients reach the depth through the Gaussian means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeansGradient {
    /// As the release trains: the means are constants.
    #[default]
    Detached,
    /// The rendering losses also train the depth.
    Through,
}

/// The per-pixel rows of a saved scene ([`crate::saved`]), each `[M, ..]` as [`PixelGaussians`] holds them.
pub(crate) struct SavedRows {
    pub means: Tensor<2>,
    pub quats_wxyz: Tensor<2>,
    pub scales: Tensor<2>,
    pub colors: Tensor<2>,
    pub opacity: Tensor<1>,
    pub lifespan: Tensor<1>,
    pub source_time: Tensor<1>,
    pub dynamic_logit: Option<Tensor<1>>,
    pub velocity: Option<Tensor<2>>,
}

/// Which way [`PixelGaussians::rotate_rows`] turns vectors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axes {
    CameraToWorld,
    WorldToCamera,
}

/// `M = S · H · W` Gaussians, one per input pixel.
#[derive(Debug, Clone)]
pub struct PixelGaussians {
    pub views: Vec<InputView>,
    pub size: ImageSize,
    /// `[M, 3]` world coordinates.
    pub means: Tensor<2>,
    /// `[M, 4]` unit quaternions, `w x y z`.
    pub quats_wxyz: Tensor<2>,
    /// `[M, 3]` linear scales.
    pub scales: Tensor<2>,
    /// `[M, 3]` RGB.
    pub colors: Tensor<2>,
    /// `[M]` opacity before the static/dynamic split.
    pub opacity: Tensor<1>,
    /// `[M]` dynamic logits; `None` when the model has no dynamic head (everything static).
    pub dynamic_logit: Option<Tensor<1>>,
    /// `[M]` lifespan `gamma`.
    pub lifespan: Tensor<1>,
    /// `[M]` scene time of the view each Gaussian came from.
    pub source_time: Tensor<1>,
    /// `[M, 3]` world displacement per unit of scene time, which moves a dynamic Gaussian to the target time
    /// ([`PixelGaussians::with_motion`]); `None`: dynamic Gaussians are held where they were predicted.
    pub velocity: Option<Tensor<2>>,
    /// The moving objects of the views and their trajectories ([`PixelGaussians::with_instances`]); `None`
    /// until found.
    pub(crate) instances: Option<Arc<Instances>>,
    /// The learnt displacements to the neighbouring inputs ([`PixelGaussians::with_learnt_flow`]); `None` until
    /// computed.
    pub(crate) learnt: Option<Arc<crate::displacements::LearntFlow>>,
    pub(crate) host_means: Vec<[f32; 3]>,
    pub(crate) host_velocity: Option<Vec<[f32; 3]>>,
    pub(crate) host_max_scale: Vec<f32>,
}

impl PixelGaussians {
    /// The Gaussians of a batch-of-one prediction: `maps` over `[1, S, H, W, ..]`, `depth` `[1, S, H, W]`,
    /// `dynamic_logit` `[1, S, H, W]`, and one [`InputView`] per frame.
    pub fn new(
        maps: &GaussianMaps,
        depth: Tensor<4>,
        dynamic_logit: Option<Tensor<4>>,
        views: Vec<InputView>,
        means_gradient: MeansGradient,
        unproject_at: PixelConvention,
    ) -> Result<Self, SceneError> {
        let [batch, frames, height, width] = maps.opacity.dims();
        if batch != 1 || frames != views.len() {
            return Err(SceneError::Shape {
                tensor: "gaussian maps",
                expected: format!("[1, S, H, W] with S = {} views", views.len()),
                actual: maps.opacity.dims().to_vec(),
            });
        }
        let expect = |tensor: &'static str, dims: [usize; 4]| {
            if dims == [1, frames, height, width] {
                Ok(())
            } else {
                Err(SceneError::Shape {
                    tensor,
                    expected: format!("[1, {frames}, {height}, {width}]"),
                    actual: dims.to_vec(),
                })
            }
        };
        expect("depth", depth.dims())?;
        if let Some(logit) = &dynamic_logit {
            expect("dynamic_logit", logit.dims())?;
        }
        let size = ImageSize::new(width as u32, height as u32)?;
        let device = maps.opacity.device();
        let count = frames * height * width;

        let host_depth = host_f32(depth.clone(), "depth")?;
        if let Some(i) = host_depth.iter().position(|d| !d.is_finite()) {
            return Err(SceneError::NonFinite {
                tensor: "depth",
                value: host_depth[i],
                view: i / (height * width),
                pixel: i % (height * width),
            });
        }
        let rays = Rays::new(&views, size, unproject_at);
        let host_means: Vec<[f32; 3]> = (0..count)
            .map(|i| {
                let point = rays.centre(i) + rays.direction(i) * host_depth[i] as f64;
                point.to_array().map(|v| v as f32)
            })
            .collect();

        let depth = match means_gradient {
            MeansGradient::Detached => depth.detach(),
            MeansGradient::Through => depth,
        };
        let means = rays.centres_tensor(&device) + rays.directions_tensor(&device) * depth.reshape([count, 1]);

        let flat = |tensor: Tensor<5>, channels: usize| tensor.reshape([count, channels]);
        let scales = flat(maps.scale.clone(), 3);
        let host_max_scale =
            host_f32(scales.clone(), "scales")?.chunks_exact(3).map(|s| s[0].max(s[1]).max(s[2])).collect();
        let times: Vec<f32> = views.iter().flat_map(|v| std::iter::repeat_n(v.time as f32, height * width)).collect();
        Ok(Self {
            size,
            means,
            quats_wxyz: flat(maps.rotation.clone(), 4),
            scales,
            colors: flat(maps.rgb.clone(), 3),
            opacity: maps.opacity.clone().reshape([count]),
            dynamic_logit: dynamic_logit.map(|logit| logit.reshape([count])),
            lifespan: maps.lifespan.clone().reshape([count]),
            source_time: Tensor::from_data(TensorData::new(times, [count]), &device),
            velocity: None,
            instances: None,
            learnt: None,
            host_means,
            host_velocity: None,
            host_max_scale,
            views,
        })
    }

    /// The Gaussians of a saved scene: rows already checked for their shapes and finite values.
    pub(crate) fn from_saved(views: Vec<InputView>, size: ImageSize, rows: SavedRows) -> Result<Self, SceneError> {
        let triples = |tensor: &Tensor<2>, name: &str| -> Result<Vec<[f32; 3]>, SceneError> {
            Ok(host_f32(tensor.clone(), name)?.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect())
        };
        let host_means = triples(&rows.means, "means")?;
        let host_max_scale = triples(&rows.scales, "scales")?.iter().map(|s| s[0].max(s[1]).max(s[2])).collect();
        let host_velocity = rows.velocity.as_ref().map(|v| triples(v, "velocity")).transpose()?;
        Ok(Self {
            views,
            size,
            means: rows.means,
            quats_wxyz: rows.quats_wxyz,
            scales: rows.scales,
            colors: rows.colors,
            opacity: rows.opacity,
            dynamic_logit: rows.dynamic_logit,
            lifespan: rows.lifespan,
            source_time: rows.source_time,
            velocity: rows.velocity,
            instances: None,
            learnt: None,
            host_means,
            host_velocity,
            host_max_scale,
        })
    }

    /// Adds the motion head's prediction: `velocity` `[1, S, H, W, 3]` in world units per log frame along the
    /// axes of each view's camera (OpenCV), and `frames_per_time` log frames per unit of scene time (the
    /// inverse of the timeline's rate). Stored rotated to world axes and per unit of scene time, so that a
    /// dynamic Gaussian from a view at time `s` sits at `mean + velocity · (t - s)` at time `t`.
    pub fn with_motion(mut self, velocity: Tensor<5>, frames_per_time: f64) -> Result<Self, SceneError> {
        let [_, frames, height, width, channels] = velocity.dims();
        let expected = [1, self.views.len(), self.size.height as usize, self.size.width as usize, 3];
        if velocity.dims() != expected {
            return Err(SceneError::Shape {
                tensor: "velocity",
                expected: format!("{expected:?}"),
                actual: velocity.dims().to_vec(),
            });
        }
        if !frames_per_time.is_finite() {
            return Err(SceneError::NonFiniteTime {
                what: "motion: frames per unit of scene time",
                value: frames_per_time,
            });
        }
        let per_view = height * width;
        let camera = velocity.reshape([frames * per_view, channels]);
        let world = self.rotate_rows(camera, Axes::CameraToWorld).mul_scalar(frames_per_time as f32);
        let host = host_f32(world.clone(), "velocity")?;
        if let Some(i) = host.iter().position(|v| !v.is_finite()) {
            return Err(SceneError::NonFinite {
                tensor: "velocity",
                value: host[i],
                view: i / 3 / per_view,
                pixel: i / 3 % per_view,
            });
        }
        self.host_velocity = Some(host.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect());
        self.velocity = Some(world);
        Ok(self)
    }

    /// Turns vectors `[M, 3]`, one per row, between the world's axes and those of each row's view camera
    /// (OpenCV), with that view's rotation `R` (world-from-camera): `R v` to the world, `R^T v` to the camera.
    pub fn rotate_rows(&self, rows: Tensor<2>, to: Axes) -> Tensor<2> {
        let frames = self.views.len();
        // Row vectors times M: M = R^T to the world, M = R to the camera.
        let rotations: Vec<f32> = self
            .views
            .iter()
            .flat_map(|v| {
                let r = v.camera.world_from_camera.rotation_matrix();
                (0..3).flat_map(move |i| {
                    (0..3).map(move |j| match to {
                        Axes::CameraToWorld => r.col(i)[j] as f32,
                        Axes::WorldToCamera => r.col(j)[i] as f32,
                    })
                })
            })
            .collect();
        let rotations = Tensor::<3>::from_data(TensorData::new(rotations, [frames, 3, 3]), &rows.device());
        rows.reshape([frames, self.per_view(), 3]).matmul(rotations).reshape([frames * self.per_view(), 3])
    }

    /// Finds the moving objects of the views (`dggt_instances`: dynamic pixels clustered, followed through the
    /// input times, registered rigidly), seeded by the predicted velocities when there are any. Without a dynamic
    /// head nothing moves and no instance is found.
    pub fn with_instances(mut self, settings: &InstanceSettings) -> Result<Self, SceneError> {
        let per_view = self.per_view();
        let dynamic: Vec<f32> = match &self.dynamic_logit {
            Some(logit) => {
                host_f32(logit.clone(), "dynamic logit")?.iter().map(|&l| 1.0 / (1.0 + (-l).exp())).collect()
            }
            None => vec![0.0; self.len()],
        };
        let (width, height) = (self.size.width as usize, self.size.height as usize);
        let views: Vec<ViewPoints> = self
            .views
            .iter()
            .enumerate()
            .map(|(v, view)| {
                let range = v * per_view..(v + 1) * per_view;
                ViewPoints {
                    rig_camera: view.rig_camera,
                    time: view.time,
                    width,
                    height,
                    camera_centre: view.camera.world_from_camera.translation(),
                    pixel_angle: 2.0 / (view.camera.intrinsics.fx + view.camera.intrinsics.fy),
                    points: &self.host_means[range.clone()],
                    dynamic: &dynamic[range.clone()],
                    velocity: self.host_velocity.as_ref().map(|velocity| &velocity[range]),
                }
            })
            .collect();
        let instances = find_instances(&views, settings)?;
        tracing::debug!(instances = instances.len(), "found the moving objects");
        self.instances = Some(Arc::new(instances));
        Ok(self)
    }

    /// Sets the moving objects to `instances` (read back from a file, or edited) instead of finding them; their
    /// labels must cover every view's pixels.
    pub fn with_known_instances(mut self, instances: Arc<Instances>) -> Result<Self, SceneError> {
        let per_view = self.per_view();
        let views = self.views.len();
        if instances.views() != views || (0..views).any(|v| instances.labels(v).len() != per_view) {
            return Err(SceneError::Shape {
                tensor: "instance labels",
                expected: format!("{views} views of {per_view} pixels"),
                actual: (0..instances.views()).map(|v| instances.labels(v).len()).collect(),
            });
        }
        self.instances = Some(instances);
        Ok(self)
    }

    /// The moving objects found by [`PixelGaussians::with_instances`].
    pub fn instances(&self) -> Option<&Instances> {
        self.instances.as_deref()
    }

    /// The host copy of [`PixelGaussians::velocity`] (world axes per unit of scene time), one row per Gaussian.
    pub fn host_velocity(&self) -> Option<&[[f32; 3]]> {
        self.host_velocity.as_deref()
    }

    /// The host copy of [`PixelGaussians::means`], one row per Gaussian.
    pub fn host_means(&self) -> &[[f32; 3]] {
        &self.host_means
    }

    /// Number of Gaussians `M`.
    pub fn len(&self) -> usize {
        self.host_means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.host_means.is_empty()
    }

    /// Gaussians per view (`H · W`).
    pub fn per_view(&self) -> usize {
        self.size.area()
    }
}

/// Per-pixel camera centres and world-space ray directions scaled so that `z_cam = 1`.
struct Rays {
    centres: Vec<DVec3>,
    directions: Vec<DVec3>,
    per_view: usize,
}

impl Rays {
    fn new(views: &[InputView], size: ImageSize, convention: PixelConvention) -> Self {
        let per_view = size.area();
        let mut directions = Vec::with_capacity(views.len() * per_view);
        let centres = views.iter().map(|v| v.camera.world_from_camera.translation()).collect();
        for view in views {
            let pose = &view.camera.world_from_camera;
            for row in 0..size.height {
                for column in 0..size.width {
                    let pixel = convention.coordinates(column, row);
                    directions.push(pose.transform_vector(view.camera.intrinsics.unproject(pixel, 1.0)));
                }
            }
        }
        Self { centres, directions, per_view }
    }

    fn centre(&self, i: usize) -> DVec3 {
        self.centres[i / self.per_view]
    }

    fn direction(&self, i: usize) -> DVec3 {
        self.directions[i]
    }

    fn centres_tensor(&self, device: &Device) -> Tensor<2> {
        let count = self.directions.len();
        let values: Vec<f32> = (0..count).flat_map(|i| self.centre(i).to_array().map(|v| v as f32)).collect();
        Tensor::from_data(TensorData::new(values, [count, 3]), device)
    }

    fn directions_tensor(&self, device: &Device) -> Tensor<2> {
        let count = self.directions.len();
        let values: Vec<f32> = self.directions.iter().flat_map(|d| d.to_array().map(|v| v as f32)).collect();
        Tensor::from_data(TensorData::new(values, [count, 3]), device)
    }
}
