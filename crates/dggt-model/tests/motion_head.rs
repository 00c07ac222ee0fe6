//! The motion head: built on request, absent from the release's architecture, predicting exactly zero until
//! trained, and reached by gradients through its zeroed output layer.

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
