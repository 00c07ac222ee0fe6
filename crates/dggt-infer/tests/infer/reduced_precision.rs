//! The network in f16 and bf16: the parity model of `shared/parity/dggt_tiny_s3_56x70` with its parameters
//! cast ([`Dggt::with_float_dtype`]) runs on f32 images and gives every output the f32 network gives, to within
//! what the type's precision allows.
//!
//! The bound for each output is relative to its largest f32 magnitude `m`, in units of the type's machine
//! epsilon `e` (2^-10 for f16, 2^-7 for bf16): every element within `32 e m`, the mean within `4 e m`. An error
//! from computing in the type grows with the depth of the network but stays a small multiple of `e`; a constant
//! left in f32, an overflow or a lost normalisation would either fail to run or miss by far more.

use std::path::PathBuf;

use burn::tensor::{DType, Device, FloatDType, Tensor};
use dggt_model::{Dggt, DggtOutput};
use dggt_parity::ParityVectors;

fn parity_dir() -> PathBuf {
    dggt_test_data::parity("dggt_tiny_s3_56x70")
}

fn host<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.cast(FloatDType::F32).into_data().convert::<f32>().try_into_vec::<f32>().expect("float values")
}

/// Every output a reduced-precision run is compared on: name, f32 value, reduced value.
fn outputs(exact: DggtOutput, reduced: DggtOutput) -> Vec<(&'static str, Vec<f32>, Vec<f32>)> {
    let maps = |out: &DggtOutput| out.gaussians.as_ref().expect("gs head").maps.clone();
    let (g, h) = (maps(&exact), maps(&reduced));
    let dynamic = |out: DggtOutput| host(out.instance.expect("instance head").prediction);
    vec![
        ("depth", host(exact.depth.prediction.clone()), host(reduced.depth.prediction.clone())),
        ("depth confidence", host(exact.depth.confidence.clone()), host(reduced.depth.confidence.clone())),
        ("pose encoding", host(exact.camera.pose_encoding()), host(reduced.camera.pose_encoding())),
        ("gaussian rgb", host(g.rgb), host(h.rgb)),
        ("gaussian opacity", host(g.opacity), host(h.opacity)),
        ("gaussian scale", host(g.scale), host(h.scale)),
        ("gaussian rotation", host(g.rotation), host(h.rotation)),
        ("gaussian lifespan (raw)", host(g.lifespan_raw), host(h.lifespan_raw)),
        ("dynamic logit", dynamic(exact), dynamic(reduced)),
    ]
}

fn assert_close_to_f32(dtype: FloatDType, epsilon: f32) {
    let device = Device::flex();
    let dir = parity_dir();
    let vectors = ParityVectors::open(&dir).expect("opening the parity vectors");
    let (model, _) =
        Dggt::from_checkpoint(&vectors.config, dir.join("weights.safetensors"), &device).expect("loading weights");
    let images = vectors.images(&device).expect("images");
    let exact = model.forward(images.clone()).expect("f32 forward");
    let reduced_model = model.with_float_dtype(dtype);
    let reduced = reduced_model.forward(images).expect("reduced-precision forward");

    assert_eq!(reduced.depth.prediction.dtype(), DType::from(dtype), "the heads compute in {dtype:?}");
    assert_eq!(reduced.gaussians.as_ref().unwrap().maps.rgb.dtype(), DType::F32, "Gaussian maps are f32");
    let sky = reduced_model.sky_model.as_ref().expect("sky model");
    assert_eq!(sky.bg_scales.val().dtype(), DType::F32, "the sky model stays f32");

    for (name, exact, reduced) in outputs(exact, reduced) {
        let magnitude = exact.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let errors: Vec<f32> = exact.iter().zip(&reduced).map(|(a, b)| (a - b).abs()).collect();
        assert!(reduced.iter().all(|v| v.is_finite()), "{dtype:?} {name}: non-finite values");
        let max = errors.iter().fold(0.0f32, |m, &e| m.max(e));
        let mean = errors.iter().sum::<f32>() / errors.len() as f32;
        assert!(max <= 32.0 * epsilon * magnitude, "{dtype:?} {name}: max error {max} (largest value {magnitude})");
        assert!(mean <= 4.0 * epsilon * magnitude, "{dtype:?} {name}: mean error {mean} (largest value {magnitude})");
        // Not trivially equal: the type really was used.
        assert!(max > 0.0, "{dtype:?} {name}: identical to f32, so the network did not compute in {dtype:?}");
    }
}

#[test]
fn the_network_in_f16_matches_f32_to_f16_precision() {
    assert_close_to_f32(FloatDType::F16, 2f32.powi(-10));
}

#[test]
fn the_network_in_bf16_matches_f32_to_bf16_precision() {
    assert_close_to_f32(FloatDType::BF16, 2f32.powi(-7));
}
