//! The predicted scene flow of the surface seen at an input view, in the export's units, for scoring motion,
//! from each [`DynamicMotion`] a reconstruction can move its dynamic Gaussians with (the source a table names).
//!
//! A pixel's Gaussian splits into a static part (opacity `o · (1 - p)`) and a dynamic part (`o · p`, `p` the
//! sigmoid of the dynamic logit) that moves with velocity `v`, so the surface point's expected flow is `p · v`.
//! The velocity is the network's prediction ([`DynamicMotion::Velocity`]), or the velocity of the point on its
//! object's trajectory at the view's time ([`DynamicMotion::Instances`]: the twist of the step starting there,
//! the predicted velocity for a pixel of no object). At an input view the reconstruction's pixel grid is the
//! view's own: the flow of the surface at a lidar cell is read at the cell's centre (bilinearly, as the depth
//! is). At any other view the same expectation is rasterised from the assembled Gaussians
//! (`dggt_scene::render_flow`), for the source the renders use.
//!
//! Units and axes, from the reconstruction's to the export's:
//! - the velocity is in the reconstruction's world axes (the first input view's predicted camera), world units
//!   per unit of scene time ([`PixelGaussians::velocity`]);
//! - it is rotated into the view's camera axes with the view's predicted camera, then into the log world's axes
//!   (the export flow's) with the export's camera of the view and the log's frame in the scene's world;
//! - world units become metres by the view's least-squares depth scale without shift ([`metres_per_unit`]: a
//!   displacement has no offset, and unlike D-RMSE's scale-and-shift fit it stays positive for positive depths);
//! - per unit of scene time becomes per second: divided by the log frames per unit of scene time times the
//!   seconds per log frame.

use dggt_geom::glam::{DMat3, DVec3};
use dggt_model::host::host_f32;
use dggt_scene::{DynamicMotion, PixelGaussians};

use crate::error::EvalError;
use crate::report::{MOTION_HELD, MOTION_INSTANCES, MOTION_LEARNT, MOTION_VELOCITY};

/// The description written to the reports for the motion a reconstruction renders with.
pub fn motion_label(motion: DynamicMotion) -> &'static str {
    match motion {
        DynamicMotion::Held => MOTION_HELD,
        DynamicMotion::Velocity => MOTION_VELOCITY,
        DynamicMotion::Instances => MOTION_INSTANCES,
        DynamicMotion::Learnt => MOTION_LEARNT,
    }
}

/// The expected flow `p · v` of every input pixel, as three planes per input view.
#[derive(Debug, Clone)]
pub struct InputFlow {
    /// Per input view, the x, y and z planes (`H x W`, row-major) in world axes per unit of scene time.
    planes: Vec<[Vec<f32>; 3]>,
    /// Seconds per unit of scene time.
    seconds_per_time: f64,
}

impl InputFlow {
    /// The expected flow of `pixels` under `source`; `None` for [`DynamicMotion::Held`], when the source has
    /// nothing to move them with (no velocity, no instances found), or when the time base is unknown (one input
    /// frame, or a log without a frame interval).
    pub fn of(
        pixels: &PixelGaussians,
        source: DynamicMotion,
        frames_per_time: f64,
        seconds_per_frame: Option<f64>,
    ) -> Result<Option<Self>, EvalError> {
        let velocity = match source {
            DynamicMotion::Held => None,
            DynamicMotion::Velocity => pixels.host_velocity().map(<[_]>::to_vec),
            DynamicMotion::Instances => instance_velocities(pixels),
            DynamicMotion::Learnt => pixels.learnt_velocities(),
        };
        let Some(velocity) = velocity else { return Ok(None) };
        let seconds_per_time = frames_per_time * seconds_per_frame.unwrap_or(0.0);
        if !(seconds_per_time > 0.0 && seconds_per_time.is_finite()) {
            return Ok(None);
        }
        let dynamic = match &pixels.dynamic_logit {
            Some(logit) => host_f32(logit.clone(), "dynamic logit")?.iter().map(|&l| sigmoid(l)).collect(),
            None => vec![0.0; velocity.len()],
        };
        let per_view = pixels.per_view();
        let planes = (0..pixels.views.len())
            .map(|view| {
                let range = view * per_view..(view + 1) * per_view;
                let component = |axis: usize| -> Vec<f32> {
                    range.clone().map(|pixel| dynamic[pixel] * velocity[pixel][axis]).collect()
                };
                [component(0), component(1), component(2)]
            })
            .collect();
        Ok(Some(Self { planes, seconds_per_time }))
    }

    /// The planes of input view `view` (the scene's input order).
    pub fn planes(&self, view: usize) -> &[Vec<f32>; 3] {
        &self.planes[view]
    }

    /// A flow sampled from [`InputFlow::planes`] in the export's axes and units, given the view's rotation from
    /// the reconstruction's world to the log world ([`log_from_reconstruction`]) and its metres per world unit.
    pub fn in_export_units(&self, flow: [f32; 3], log_from_world: DMat3, metres_per_unit: f64) -> [f32; 3] {
        let flow = DVec3::new(f64::from(flow[0]), f64::from(flow[1]), f64::from(flow[2]));
        let converted = log_from_world * flow * (metres_per_unit / self.seconds_per_time);
        [converted.x as f32, converted.y as f32, converted.z as f32]
    }
}

/// Every Gaussian's velocity when the instances move the dynamic ones: a pixel of an object moves with its
/// object's trajectory at its view's time, any other with its predicted velocity (zero without one); `None`
/// when no instances were found.
fn instance_velocities(pixels: &PixelGaussians) -> Option<Vec<[f32; 3]>> {
    let instances = pixels.instances()?;
    let per_view = pixels.per_view();
    let means = pixels.host_means();
    let velocities = (0..pixels.len())
        .map(|row| {
            let (view, pixel) = (row / per_view, row % per_view);
            match instances.instance_of(view, pixel) {
                Some(k) => {
                    let point = DVec3::from_array(means[row].map(f64::from));
                    let time = pixels.views[view].time;
                    instances.instances[k].trajectory.point_velocity(time, point).to_array().map(|v| v as f32)
                }
                None => pixels.host_velocity().map_or([0.0; 3], |velocity| velocity[row]),
            }
        })
        .collect();
    Some(velocities)
}

/// Metres per world unit at one view: the least-squares scale `s` minimising `sum (s p - g)^2` over the cells'
/// rendered depths `p` and lidar depths `g`; `None` without cells or when it is not positive.
pub fn metres_per_unit(predicted_depth: &[f32], true_depth: &[f32]) -> Option<f64> {
    let (cross, square) = predicted_depth
        .iter()
        .zip(true_depth)
        .map(|(&p, &g)| (f64::from(p), f64::from(g)))
        .fold((0.0, 0.0), |(cross, square), (p, g)| (cross + p * g, square + p * p));
    let scale = cross / square;
    (scale > 0.0 && scale.is_finite()).then_some(scale)
}

/// The rotation taking a vector in the reconstruction's world axes into the log world's axes at one view:
/// into the view's camera axes by its predicted camera, out of them by the export's camera of the view, then
/// from the scene's world into the log world.
pub fn log_from_reconstruction(
    world_from_log: DMat3,
    true_world_from_camera: DMat3,
    predicted_world_from_camera: DMat3,
) -> DMat3 {
    world_from_log.transpose() * true_world_from_camera * predicted_world_from_camera.transpose()
}

fn sigmoid(logit: f32) -> f32 {
    1.0 / (1.0 + (-logit).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flow(seconds_per_time: f64) -> InputFlow {
        InputFlow { planes: Vec::new(), seconds_per_time }
    }

    #[test]
    fn the_depth_scale_fits_without_shift() {
        assert_eq!(metres_per_unit(&[1.0, 2.0, 4.0], &[3.0, 6.0, 12.0]), Some(3.0));
        assert_eq!(metres_per_unit(&[], &[]), None, "no cells");
        assert_eq!(metres_per_unit(&[1.0, 2.0], &[-1.0, -2.0]), None, "a negative scale");
    }

    #[test]
    fn identical_frames_only_change_units() {
        // Two world units per scene time, 0.5 s per scene time, 3 m per world unit: 12 m/s.
        let got = flow(0.5).in_export_units([2.0, 0.0, -1.0], DMat3::IDENTITY, 3.0);
        assert_eq!(got, [12.0, 0.0, -6.0]);
    }

    #[test]
    fn the_predicted_camera_is_undone_and_the_true_one_applied() {
        // The reconstruction's world is the view's predicted camera turned 90 degrees about z; the export's
        // camera is turned 90 degrees about x in the scene world, which is the log world shifted (no rotation).
        let predicted = DMat3::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let truth = DMat3::from_rotation_x(std::f64::consts::FRAC_PI_2);
        let rotation = log_from_reconstruction(DMat3::IDENTITY, truth, predicted);
        // World +y is the predicted camera's +x (the z-turn takes camera x to world y), which the export's camera
        // (x fixed by the x-turn) puts along the log's +x.
        let got = flow(1.0).in_export_units([0.0, 1.0, 0.0], rotation, 1.0);
        let expected = [1.0, 0.0, 0.0];
        assert!(got.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6), "{got:?}");
        // The camera's +z (world +z under the z-turn) becomes the x-turned camera's z: log -y.
        let got = flow(1.0).in_export_units([0.0, 0.0, 1.0], rotation, 1.0);
        let expected = [0.0, -1.0, 0.0];
        assert!(got.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6), "{got:?}");
    }

    #[test]
    fn the_log_frame_is_rotated_out_of_the_scene_world() {
        // The scene's world is the log world turned 90 degrees about z: a vector along the scene's +x is the
        // log's -y.
        let world_from_log = DMat3::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let rotation = log_from_reconstruction(world_from_log, DMat3::IDENTITY, DMat3::IDENTITY);
        let got = flow(1.0).in_export_units([1.0, 0.0, 0.0], rotation, 1.0);
        let expected = [0.0, -1.0, 0.0];
        assert!(got.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-6), "{got:?}");
    }
}
