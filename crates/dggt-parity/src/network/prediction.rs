//! One forward pass of the network on the vectors' images, and what the reference outputs need derived from it,
//! each computed once on demand: the cameras decoded from the pose encoding, the Gaussian means unprojected
//! from the depth, the sky model coloured with those cameras, the lifespan decay and the release's render.

use std::cell::OnceCell;

use burn::tensor::{Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics, PixelConvention, PoseEncoding, unproject_depth_map};
use dggt_model::dpt::{DptOutput, DptPrediction};
use dggt_model::lifespan::{frame_times, opacity_at, static_opacity};
use dggt_model::sky::{SkyGaussians, SkyProjection};
use dggt_model::{Dggt, DggtOutput, GaussianOutput};

use crate::network::comparison::{Actual, host};
use crate::network::release_render::{SceneInputs, SceneRender, render_scene};
use crate::network::reproduce_error::ReproduceError;
use crate::vectors::HostTensor;

/// One forward pass and what is derived from it on demand.
pub(super) struct Prediction<'a> {
    pub model: &'a Dggt,
    pub images: Tensor<5>,
    pub out: DggtOutput,
    pub size: ImageSize,
    cameras: OnceCell<Result<Vec<(CameraFromWorld, PinholeIntrinsics)>, ReproduceError>>,
    sky: OnceCell<Result<(SkyProjection, SkyGaussians), ReproduceError>>,
    /// The vectors' `sky_mask` input, `[B, S, 3, H, W]` (1 = sky).
    pub sky_mask: Option<HostTensor>,
    scene: OnceCell<Result<SceneRender, ReproduceError>>,
}

impl<'a> Prediction<'a> {
    pub fn new(model: &'a Dggt, images: Tensor<5>, out: DggtOutput) -> Self {
        let [.., height, width] = images.dims();
        let size = ImageSize::new(width as u32, height as u32).expect("the forward pass accepted the images");
        Self {
            model,
            images,
            out,
            size,
            cameras: OnceCell::new(),
            sky: OnceCell::new(),
            sky_mask: None,
            scene: OnceCell::new(),
        }
    }

    /// `[B, S, ..rest]`.
    pub fn per_frame(&self, rest: &[usize]) -> Vec<usize> {
        let [batch, frames, ..] = self.images.dims();
        [batch, frames].iter().chain(rest).copied().collect()
    }

    pub fn dpt(&self, head: &'static str) -> Result<&DptOutput, ReproduceError> {
        match head {
            "depth_head" => Ok(&self.out.depth.dpt),
            "point_head" => Ok(&self.points()?.dpt),
            "gs_head" => Ok(&self.gaussians()?.dpt),
            "instance_head" => Ok(&self.instance()?.dpt),
            "semantic_head" => Ok(&self.semantic()?.dpt),
            other => Err(ReproduceError::NoPart(other)),
        }
    }

    pub fn gaussians(&self) -> Result<&GaussianOutput, ReproduceError> {
        self.out.gaussians.as_ref().ok_or(ReproduceError::NoPart("gs_head"))
    }

    pub fn instance(&self) -> Result<&DptPrediction, ReproduceError> {
        self.out.instance.as_ref().ok_or(ReproduceError::NoPart("instance_head"))
    }

    pub fn points(&self) -> Result<&DptPrediction, ReproduceError> {
        self.out.points.as_ref().ok_or(ReproduceError::NotRun("point_head"))
    }

    pub fn semantic(&self) -> Result<&DptPrediction, ReproduceError> {
        self.out.semantic.as_ref().ok_or(ReproduceError::NoPart("semantic_head"))
    }

    /// The dynamic logit, channel 0 of the instance prediction, `[B, S, H, W]`.
    pub fn dynamic_logit(&self) -> Result<Tensor<4>, ReproduceError> {
        Ok(self.instance()?.prediction.clone().narrow(4, 0, 1).squeeze_dim::<4>(4))
    }

    /// The camera of every frame (batch-major), decoded from the pose encoding.
    pub fn cameras(&self) -> Result<&[(CameraFromWorld, PinholeIntrinsics)], ReproduceError> {
        let decoded = self.cameras.get_or_init(|| {
            let encodings = HostTensor::from_tensor(self.out.camera.pose_encoding()).values;
            encodings
                .chunks(9)
                .map(|frame| {
                    let values: [f64; 9] = std::array::from_fn(|i| frame[i] as f64);
                    PoseEncoding::from_array(values).decode(self.size).map_err(ReproduceError::PoseDecoding)
                })
                .collect()
        });
        decoded.as_deref().map_err(Clone::clone)
    }

    /// The depth of every frame unprojected at integer pixel coordinates (as the release does), in world or
    /// camera space, `[B, S, H, W, 3]`.
    pub fn means(&self, world: bool) -> Result<Actual, ReproduceError> {
        let depth = HostTensor::from_tensor(self.out.depth.prediction.clone()).values;
        let mut values = Vec::with_capacity(depth.len() * 3);
        let width = self.size.width as usize;
        for ((camera_from_world, k), depth) in self.cameras()?.iter().zip(depth.chunks(self.size.area())) {
            if world {
                let convention = PixelConvention::Integer;
                let points = unproject_depth_map(depth, self.size, k, camera_from_world, convention)
                    .map_err(ReproduceError::Unprojection)?;
                values.extend(points.iter().flat_map(|p| p.to_array()).map(|v| v as f32));
            } else {
                values.extend(depth.iter().enumerate().flat_map(|(i, &d)| {
                    let pixel = PixelConvention::Integer.coordinates((i % width) as u32, (i / width) as u32);
                    k.unproject(pixel, d as f64).to_array().map(|v| v as f32)
                }));
            }
        }
        let shape = self.per_frame(&[self.size.height as usize, width, 3]);
        Ok(host(HostTensor::new(shape, values)))
    }

    /// The sky points projected with the predicted cameras and coloured from the input images.
    pub fn sky(&self) -> Result<&(SkyProjection, SkyGaussians), ReproduceError> {
        let sky = self.sky.get_or_init(|| {
            let model = self.model.sky_model.as_ref().ok_or(ReproduceError::NoPart("sky_model"))?;
            let [batch, frames, channels, height, width] = self.images.dims();
            if batch != 1 {
                let problem = format!("the sky model colours one scene; the vectors hold {batch}");
                return Err(ReproduceError::Input { input: "images", problem });
            }
            let cameras = self.cameras()?;
            let images = self.images.clone().reshape([frames, channels, height, width]);
            Ok((model.project(cameras, self.size), model.gaussians(images, cameras)))
        });
        sky.as_ref().map_err(Clone::clone)
    }

    /// `[1, S, ..]` to `[S, ..]`.
    pub fn frames(&self, tensor: Tensor<4>) -> Tensor<3> {
        tensor.squeeze_dim::<3>(0)
    }

    /// The Gaussian opacity split by the dynamic logit with `split`, `[B, S, H, W]`.
    pub fn split_opacity(&self, split: fn(Tensor<4>, Tensor<4>) -> Tensor<4>) -> Result<Tensor<4>, ReproduceError> {
        Ok(split(self.gaussians()?.maps.opacity.clone(), self.dynamic_logit()?))
    }

    /// Every frame's static opacity seen at every frame's time, `[render frame, source frame, H, W]`.
    pub fn static_opacity_at_t(&self) -> Result<Tensor<4>, ReproduceError> {
        let alpha = self.frames(self.split_opacity(static_opacity)?);
        let lifespan = self.frames(self.gaussians()?.maps.lifespan.clone());
        let [frames, height, width] = alpha.dims();
        let times = frame_times(frames);
        let source: Vec<f32> = times.iter().flat_map(|&t| std::iter::repeat_n(t as f32, height * width)).collect();
        let source = Tensor::<3>::from_data(TensorData::new(source, [frames, height, width]), &alpha.device());
        let at = |&t: &f64| opacity_at(alpha.clone(), lifespan.clone(), source.clone(), t);
        Ok(Tensor::stack(times.iter().map(at).collect(), 0))
    }

    /// Per pixel of every frame, row-major: not sky in the vectors' `sky_mask` (any channel 0).
    pub fn non_sky(&self) -> Result<Vec<bool>, ReproduceError> {
        let mask = self
            .sky_mask
            .as_ref()
            .ok_or_else(|| ReproduceError::Input { input: "sky_mask", problem: "not in inputs.safetensors".into() })?;
        let pixels = self.size.area();
        if mask.values.len() != self.images.dims()[..2].iter().product::<usize>() * 3 * pixels {
            let problem = format!("{:?}, not [B, S, 3, H, W]", mask.shape);
            return Err(ReproduceError::Input { input: "sky_mask", problem });
        }
        Ok(mask
            .values
            .chunks(3 * pixels)
            .flat_map(|frame| (0..pixels).map(move |i| (0..3).any(|c| frame[c * pixels + i] == 0.0)))
            .collect())
    }

    /// The release's inference render of the scene.
    pub fn scene(&self) -> Result<&SceneRender, ReproduceError> {
        let scene = self.scene.get_or_init(|| {
            let means = self.means(true)?.tensor.to_tensor::<5>(&self.images.device()).expect("[B, S, H, W, 3] means");
            let non_sky = self.non_sky()?;
            let inputs = SceneInputs {
                maps: &self.gaussians()?.maps,
                dynamic_logit: self.dynamic_logit()?,
                means,
                non_sky: &non_sky,
                cameras: self.cameras()?,
                sky: &self.sky()?.1,
            };
            Ok(render_scene(&inputs, self.size)?)
        });
        scene.as_ref().map_err(Clone::clone)
    }

    /// Sky pixel coordinates `[S, N, 2]`, compared where `mask` holds: behind a camera the release's values are
    /// clamped garbage, and in front of it but far outside the image (grazing depths) `x / z` amplifies the
    /// reference's `f32` rounding beyond any fixed relative tolerance. Whether points are in front and seen is
    /// compared exactly by `sky.in_front` and `sky.view_mask`.
    pub fn sky_pixels(&self, values: Vec<f32>, mask: Vec<bool>) -> Actual {
        let points = values.len() / 2;
        let views = self.images.dims()[1];
        let mut actual = host(HostTensor::new(vec![views, points / views, 2], values));
        actual.mask = Some(mask);
        actual.note = Some("compared where the point is seen: in front of the camera, inside the image");
        actual
    }
}
