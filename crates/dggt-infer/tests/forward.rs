//! The frame-chunked forward pass gives the network's own outputs.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_infer::forward_chunked;
use dggt_model::{Dggt, ModelConfig};

fn max_difference<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    assert_eq!(a.dims(), b.dims());
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
        let chunked = forward_chunked(&model, images.clone(), chunk).unwrap();
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
