//! Predicted motion, from the motion head or from the Gaussian head's velocity channels: built on request,
//! absent from the release's architecture, predicting exactly zero until trained, and reached by gradients
//! through the zeroed output rows.

use burn::tensor::{Device, Distribution, Tensor};
use dggt_model::{Dggt, ExtraHeads, ModelConfig};

#[test]
fn a_fresh_motion_head_predicts_zero_and_still_learns() {
    assert!(ModelConfig::dggt().motion_head.is_none() && ModelConfig::tiny().motion_head.is_none());
    let config = ModelConfig::tiny().with_motion_head();
    config.validate().expect("the motion head's sizes are valid");
    let device = Device::flex().autodiff();
    device.seed(3);
    let model = Dggt::new(&config, &device).unwrap();
    assert!(model.built_prefixes().contains(&"motion_head."));

    let images = Tensor::<5>::random([1, 2, 3, 28, 42], Distribution::Uniform(0.0, 1.0), &device);
    let out = model.forward_with(images, ExtraHeads::NONE).unwrap();
    let motion = out.motion.expect("a motion prediction");
    assert_eq!(motion.prediction.dims(), [1, 2, 28, 42, 3]);
    let largest = motion.prediction.clone().abs().max().into_scalar::<f32>();
    assert_eq!(largest, 0.0, "a fresh head holds every Gaussian");

    let grads = motion.prediction.mul_scalar(1.5).sum().backward();
    let head = model.motion_head.as_ref().unwrap();
    let weight = head.scratch.output_conv2.out.weight.val().grad(&grads).expect("output layer gradient");
    assert!(weight.abs().max().into_scalar::<f32>() > 0.0, "the zeroed output layer is trained");
}

#[test]
fn a_motion_head_of_the_wrong_width_is_refused() {
    let mut config = ModelConfig::tiny().with_motion_head();
    config.motion_head.as_mut().unwrap().dim_in = 64;
    let error = config.validate().unwrap_err().to_string();
    assert!(error.contains("motion_head"), "{error}");
}

#[test]
fn gaussian_velocity_channels_start_at_zero_and_leave_the_gaussians_alone() {
    assert!(!ModelConfig::dggt().predicts_motion() && !ModelConfig::tiny().predicts_motion());
    assert!(ModelConfig::tiny().with_motion_head().predicts_motion());
    let config = ModelConfig::tiny().with_gaussian_velocity();
    config.validate().expect("the velocity channels' sizes are valid");
    assert!(config.predicts_motion() && config.motion_head.is_none());
    let device = Device::flex().autodiff();
    device.seed(4);
    let model = Dggt::new(&config, &device).unwrap();

    let images = Tensor::<5>::random([1, 2, 3, 28, 42], Distribution::Uniform(0.0, 1.0), &device);
    let out = model.forward_with(images, ExtraHeads::NONE).unwrap();
    let gaussians = out.gaussians.as_ref().expect("a Gaussian head");
    assert_eq!(gaussians.dpt.raw.dims(), [1, 2, 28, 42, 15]);
    let velocity = out.velocity().expect("velocities from the Gaussian head");
    assert_eq!(velocity.dims(), [1, 2, 28, 42, 3]);
    assert_eq!(velocity.clone().abs().max().into_scalar::<f32>(), 0.0, "a fresh head holds every Gaussian");
    // Only the velocity rows were zeroed: the Gaussian channels still vary from pixel to pixel.
    let opacity = gaussians.maps.opacity.clone();
    let spread = opacity.clone().max().into_scalar::<f32>() - opacity.min().into_scalar::<f32>();
    assert!(spread > 1e-3, "opacities spread {spread}");

    let grads = velocity.mul_scalar(2.0).sum().backward();
    let head = model.gs_head.as_ref().unwrap();
    let weight = head.scratch.output_conv2.out.weight.val().grad(&grads).expect("output layer gradient");
    let rows = |range: std::ops::Range<usize>| weight.clone().narrow(0, range.start, range.len()).abs().max();
    assert!(rows(12..15).into_scalar::<f32>() > 0.0, "the zeroed velocity rows are trained");
    assert_eq!(rows(0..12).into_scalar::<f32>(), 0.0, "the velocity alone reaches only its own rows");

    // A Gaussian head whose channel count does not fit its velocity flag is refused.
    let mut config = ModelConfig::tiny().with_gaussian_velocity();
    config.gs_head.as_mut().unwrap().output_dim = 12;
    let error = config.validate().unwrap_err().to_string();
    assert!(error.contains("gs_head") && error.contains("15"), "{error}");
}
