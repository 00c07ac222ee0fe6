//! The frame-chunked forward pass gives the network's own outputs.

use burn::module::Param;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_infer::{MotionPath, forward_chunked, is_still};
use dggt_model::{Dggt, ModelConfig};

fn max_difference<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    assert_eq!(a.dims(), b.dims(), "the two tensors compared have one shape");
    let a = a.into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
    let b = b.into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
    a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn chunked_heads_match_the_full_forward() {
    let device = Device::flex();
    device.seed(3);
    let mut config = ModelConfig::tiny();
    config.gs_head.as_mut().unwrap().color_skip = true;
    let model = Dggt::new(&config, &device).unwrap();
    let (frames, h, w) = (5, 42, 56);
    let pixels: Vec<f32> = (0..frames * 3 * h * w).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let images = Tensor::<5>::from_data(TensorData::new(pixels, [1, frames, 3, h, w]), &device);

    let full = model.forward(images.clone()).unwrap();
    for chunk in [1, 2, 5] {
        let chunked = forward_chunked(&model, images.clone(), chunk, MotionPath::Always).unwrap();
        let depth = full.depth.prediction.clone().narrow(4, 0, 1).squeeze_dim::<4>(4);
        assert!(max_difference(depth, chunked.depth.clone()) < 1e-5, "depth, chunk {chunk}");
        let dynamic = full.instance.as_ref().unwrap().prediction.clone().narrow(4, 0, 1).squeeze_dim::<4>(4);
        assert!(max_difference(dynamic, chunked.dynamic_logit.clone().unwrap()) < 1e-5, "dynamic, chunk {chunk}");
        let (a, b) = (&full.gaussians.as_ref().unwrap().maps, chunked.gaussians.as_ref().unwrap());
        assert!(max_difference(a.rgb.clone(), b.rgb.clone()) < 1e-5, "colours, chunk {chunk}");
        assert!(max_difference(a.opacity.clone(), b.opacity.clone()) < 1e-5, "opacity, chunk {chunk}");
        assert!(max_difference(a.scale.clone(), b.scale.clone()) < 1e-5, "scales, chunk {chunk}");
        assert!(max_difference(a.rotation.clone(), b.rotation.clone()) < 1e-5, "rotations, chunk {chunk}");
        assert!(max_difference(a.lifespan_raw.clone(), b.lifespan_raw.clone()) < 1e-5, "lifespan, chunk {chunk}");
        let encoding = full.camera.pose_encoding();
        assert!(max_difference(encoding, chunked.pose_encoding()) < 1e-6, "cameras, chunk {chunk}");
    }
}

/// Sets a DPT head's last 1x1 convolution to output `value` on every channel whatever its input.
fn constant_output(head: &mut dggt_model::dpt::DptHead, value: f32) {
    let out = &mut head.scratch.output_conv2.out;
    let device = out.weight.device();
    out.weight = Param::from_tensor(Tensor::zeros(out.weight.dims(), &device));
    let channels = out.weight.dims()[0];
    out.bias = Some(Param::from_tensor(Tensor::full([channels], value, &device)));
}

#[test]
fn the_motion_head_is_skipped_only_on_frames_without_possibly_dynamic_pixels() {
    let device = Device::flex();
    device.seed(4);
    let mut model = Dggt::new(&ModelConfig::tiny().with_motion_head(), &device).unwrap();
    constant_output(model.motion_head.as_mut().unwrap(), 0.25);
    let (frames, h, w) = (4, 28, 42);
    let pixels: Vec<f32> = (0..frames * 3 * h * w).map(|i| ((i * 104_729) % 997) as f32 / 997.0).collect();
    let images = Tensor::<5>::from_data(TensorData::new(pixels, [1, frames, 3, h, w]), &device);
    let run = |model: &Dggt, motion| forward_chunked(model, images.clone(), 2, motion).unwrap();

    // A fresh instance head's logits are near 0: every pixel may be dynamic, the motion head runs.
    let (always, planned) = (run(&model, MotionPath::Always), run(&model, MotionPath::WhereDynamic));
    assert_eq!((always.motion_skipped_frames, planned.motion_skipped_frames), (0, 0));
    assert_eq!(max_difference(always.velocity.unwrap(), planned.velocity.unwrap()), 0.0, "velocities alike");

    // Logits of -6 everywhere: sigmoid below 1/255, no dynamic Gaussian can be drawn, the head is skipped.
    constant_output(model.instance_head.as_mut().unwrap(), -6.0);
    let (always, planned) = (run(&model, MotionPath::Always), run(&model, MotionPath::WhereDynamic));
    assert_eq!((always.motion_skipped_frames, planned.motion_skipped_frames), (0, frames));
    let zeros = Tensor::<5>::zeros([1, frames, h, w, 3], &device);
    assert_eq!(max_difference(planned.velocity.unwrap(), zeros.clone()), 0.0);
    assert!(max_difference(always.velocity.unwrap(), zeros) > 0.2, "the head predicts when it runs");
    assert_eq!(max_difference(always.depth, planned.depth), 0.0, "other outputs are unchanged");

    // Just above the bound the head runs.
    assert!(is_still(-5.6) && !is_still(-5.5));
}
