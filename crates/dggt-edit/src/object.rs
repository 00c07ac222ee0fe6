//! An object taken out of one reconstruction and drawn in another: its Gaussians as each input time saw them
//! (the dynamic ones, opacity `o · sigmoid(dynamic logit)`), its trajectory, and the rigid map from its world to
//! the destination's. At a time `t` the object is drawn from its appearance nearest in time, moved along its
//! trajectory to `t` (held before its first and after its last appearance), then mapped.

use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_formats::ply::GaussianCloud;
use dggt_geom::glam::{DQuat, DVec3};
use dggt_instances::{Instances, RigidMotion};
use dggt_model::host::host_f32;
use dggt_scene::Scene4d;
use dggt_splat::{GaussianTensors, OpacityTensor};

use crate::error::EditError;

/// One object ready to be drawn in another scene.
#[derive(Debug, Clone)]
pub struct CarriedObject {
    /// Per appearance, in time order: its scene time and Gaussians then (source world).
    appearances: Vec<(f64, GaussianCloud)>,
    /// The object alone (position 0), for its motion between times.
    motion: Arc<Instances>,
    /// Source world -> destination world.
    to_destination: RigidMotion,
}

impl CarriedObject {
    /// Instance `position` of `source` (an index into its instance list), mapped by `to_destination`.
    pub fn take(
        source: &Scene4d,
        position: usize,
        to_destination: RigidMotion,
        argument: &str,
    ) -> Result<Self, EditError> {
        let pixels = &source.pixels;
        let found = pixels.instances().expect("the caller checked the source has instances");
        let logit = pixels
            .dynamic_logit
            .as_ref()
            .ok_or_else(|| EditError::argument(argument, "the source scene has no dynamic Gaussians"))?;
        let dynamic = burn::tensor::activation::sigmoid(logit.clone()) * pixels.opacity.clone();
        let host = Rows {
            means: host_f32(pixels.means.clone(), "means")?,
            quats: host_f32(pixels.quats_wxyz.clone(), "rotations")?,
            scales: host_f32(pixels.scales.clone(), "scales")?,
            colors: host_f32(pixels.colors.clone(), "colours")?,
            opacity: host_f32(dynamic, "dynamic opacity")?,
        };
        let per_view = pixels.per_view();
        let instance = &found.instances[position];
        let appearances = instance
            .appearances
            .iter()
            .map(|appearance| {
                let mut cloud = GaussianCloud::default();
                for &view in &appearance.views {
                    let labels = found.labels(view);
                    for pixel in (0..per_view).filter(|&p| labels[p] as usize == position) {
                        host.push(view * per_view + pixel, &mut cloud);
                    }
                }
                (appearance.time, cloud)
            })
            .collect();
        let alone = Instances::from_parts(vec![instance.clone()], Vec::new()).expect("no labels to check");
        Ok(Self { appearances, motion: Arc::new(alone), to_destination })
    }

    /// How many Gaussians the object is drawn with at its largest appearance.
    pub fn largest(&self) -> usize {
        self.appearances.iter().map(|(_, cloud)| cloud.len()).max().unwrap_or(0)
    }

    /// The object's Gaussians at scene time `time` in the destination's world.
    pub fn cloud_at(&self, time: f64) -> GaussianCloud {
        let Some((from, cloud)) =
            self.appearances.iter().min_by(|a, b| (a.0 - time).abs().total_cmp(&(b.0 - time).abs()))
        else {
            return GaussianCloud::default();
        };
        let motion = self.to_destination.after(&self.motion.motion(0, *from, time));
        moved(cloud, &motion)
    }
}

/// The host rows of a scene's per-pixel Gaussians.
struct Rows {
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    colors: Vec<f32>,
    opacity: Vec<f32>,
}

impl Rows {
    fn push(&self, row: usize, cloud: &mut GaussianCloud) {
        let three = |values: &[f32]| [values[row * 3], values[row * 3 + 1], values[row * 3 + 2]];
        cloud.means.push(three(&self.means));
        cloud.quats_wxyz.push(std::array::from_fn(|k| self.quats[row * 4 + k]));
        cloud.scales.push(three(&self.scales));
        cloud.colors.push(three(&self.colors));
        cloud.opacities.push(self.opacity[row]);
    }
}

/// `cloud` moved rigidly: means `R m + t`, rotations `r ⊗ q`.
pub fn moved(cloud: &GaussianCloud, motion: &RigidMotion) -> GaussianCloud {
    let mut out = cloud.clone();
    for mean in &mut out.means {
        *mean = motion.apply(DVec3::from_array(mean.map(f64::from))).to_array().map(|v| v as f32);
    }
    for quat in &mut out.quats_wxyz {
        let [w, x, y, z] = quat.map(f64::from);
        let turned = motion.rotation * DQuat::from_xyzw(x, y, z, w);
        *quat = [turned.w, turned.x, turned.y, turned.z].map(|v| v as f32);
    }
    out
}

/// `cloud` as rasteriser tensors on `device`.
pub fn tensors(cloud: &GaussianCloud, device: &Device) -> GaussianTensors {
    let n = cloud.len();
    let flat = |rows: Vec<f32>, columns: usize| Tensor::<2>::from_data(TensorData::new(rows, [n, columns]), device);
    GaussianTensors {
        means: flat(cloud.means.concat(), 3),
        quats_wxyz: flat(cloud.quats_wxyz.concat(), 4),
        scales: flat(cloud.scales.concat(), 3),
        opacities: OpacityTensor::Shared(Tensor::from_data(TensorData::new(cloud.opacities.clone(), [n]), device)),
        colors: flat(cloud.colors.concat(), 3),
    }
}

/// One opacity per Gaussian: a scene's assembly gives one; of per-view opacities, the first view's.
pub fn shared_opacity(opacities: OpacityTensor) -> Tensor<1> {
    match opacities {
        OpacityTensor::Shared(shared) => shared,
        OpacityTensor::PerView(per_view) => per_view.narrow(0, 0, 1).squeeze_dim::<1>(0),
    }
}

/// Rasteriser tensors back on the host (one opacity per Gaussian).
pub fn cloud_of(gaussians: &GaussianTensors) -> Result<GaussianCloud, EditError> {
    let rows = |tensor: &Tensor<2>, name: &str| host_f32(tensor.clone(), name);
    let opacities = host_f32(shared_opacity(gaussians.opacities.clone()), "opacities")?;
    let three = |values: Vec<f32>| values.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect();
    Ok(GaussianCloud {
        means: three(rows(&gaussians.means, "means")?),
        quats_wxyz: rows(&gaussians.quats_wxyz, "rotations")?
            .chunks_exact(4)
            .map(|q| [q[0], q[1], q[2], q[3]])
            .collect(),
        scales: three(rows(&gaussians.scales, "scales")?),
        opacities,
        colors: three(rows(&gaussians.colors, "colours")?),
    })
}
