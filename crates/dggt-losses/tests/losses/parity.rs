//! Parity with the reference vectors of `shared/parity/metrics` (scikit-image 0.26 PSNR/SSIM, lpips 0.1.4
//! LPIPS-Alex with seeded AlexNet weights and the released linear weights, a VGG-16 Gram loss with seeded
//! weights). The folder is `$DGGT_PARITY_DIR/metrics`; without it these tests fail.
//!
//! Tolerances: scalars (PSNR, SSIM, LPIPS, Gram losses) within 1e-4 relative; feature maps and Gram
//! matrices within 1e-4 of their largest magnitude; PSNR and SSIM within 1e-6 relative. The Gram losses are
//! allowed 1e-3 relative: each is a mean of squared differences of two nearly equal f32 Gram matrices, so the
//! matrices' 1e-7-level rounding is amplified by the cancellation (seen: up to 2.2e-4). The full SSIM map is
//! compared within 1e-4 absolute: skimage keeps its maps in f32, where `E[x^2] - E[x]^2` cancels to ~1e-7
//! absolute and the denominator `vx + vy + C2` can be as small as `C2 = 9e-4`, bounding its own error near
//! 1e-4; this crate computes in f64. The map's borders (reflected windows) are included in that check.

use std::collections::HashMap;
use std::sync::OnceLock;

use crate::common::{Host, max_err_rel_to_max, metrics_dir, nchw_to_nhwc, read_safetensors, rel_err, values};
use burn::tensor::{Device, Tensor};
use dggt_losses::lpips::LpipsInput;
use dggt_losses::{GramLoss, Lpips, LpipsKind};
use dggt_metrics::{ImageShape, image_metrics, psnr, ssim, ssim_map};

const SCALAR_RTOL: f64 = 1e-4;
const MAP_RTOL: f64 = 1e-4;
const SSIM_MAP_ATOL: f64 = 1e-4;

struct Vectors {
    /// `[2, 64, 80, 3]` rendered and target images.
    img0: Host,
    img1: Host,
    outputs: HashMap<String, Host>,
}

fn vectors() -> &'static Vectors {
    static VECTORS: OnceLock<Vectors> = OnceLock::new();
    VECTORS.get_or_init(|| {
        let dir = metrics_dir();
        let inputs = read_safetensors(&dir.join("inputs.safetensors"));
        Vectors {
            img0: nchw_to_nhwc(&inputs["img0"]),
            img1: nchw_to_nhwc(&inputs["img1"]),
            outputs: read_safetensors(&dir.join("outputs.safetensors")),
        }
    })
}

fn output(name: &str) -> &'static Host {
    vectors().outputs.get(name).unwrap_or_else(|| panic!("reference output {name} missing"))
}

fn assert_scalars(what: &str, got: &[f64], expected: &[f32], rtol: f64) {
    assert_eq!(got.len(), expected.len(), "{what}: count");
    for (i, (&g, &e)) in got.iter().zip(expected).enumerate() {
        let err = rel_err(g, e as f64, 1e-12);
        println!("{what}[{i}]: got {g:.9e}, reference {e:.9e}, relative error {err:.2e}");
        assert!(err <= rtol, "{what}[{i}]: got {g}, reference {e}, relative error {err:.3e} > {rtol:.0e}");
    }
}

fn image_shape() -> ImageShape {
    let s = &vectors().img0.shape;
    ImageShape::new(s[1], s[2], s[3])
}

#[test]
fn psnr_matches_skimage() {
    let v = vectors();
    let got: Vec<f64> = (0..2).map(|i| psnr(&v.img0.index(i).values, &v.img1.index(i).values).unwrap()).collect();
    assert_scalars("psnr", &got, &output("psnr").values, 1e-6);
}

#[test]
fn ssim_matches_skimage() {
    let v = vectors();
    let results: Vec<_> =
        (0..2).map(|i| ssim(&v.img0.index(i).values, &v.img1.index(i).values, image_shape()).unwrap()).collect();
    let values: Vec<f64> = results.iter().map(|r| r.value).collect();
    assert_scalars("ssim", &values, &output("ssim").values, 1e-6);
    assert_scalars("ssim_float64_inputs", &values, &output("ssim_float64_inputs").values, 1e-6);
    let per_channel: Vec<f64> = results.iter().flat_map(|r| r.per_channel.clone()).collect();
    assert_scalars("ssim_per_channel", &per_channel, &output("ssim_per_channel").values, 1e-6);
}

#[test]
fn ssim_map_matches_skimage_including_borders() {
    let v = vectors();
    let reference = output("ssim_map");
    let (mut worst, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for i in 0..2 {
        let map = ssim_map(&v.img0.index(i).values, &v.img1.index(i).values, image_shape()).unwrap();
        for (g, e) in map.iter().zip(&reference.index(i).values) {
            let d = (g - *e as f64).abs();
            worst = worst.max(d);
            sum += d;
            count += 1;
        }
    }
    println!("ssim_map: largest absolute difference {worst:.2e}, mean {:.2e}", sum / count as f64);
    assert!(worst < SSIM_MAP_ATOL, "ssim_map differs by {worst}");
}

#[test]
fn image_metrics_on_tensors_match() {
    let device = Device::flex();
    let v = vectors();
    let metrics = image_metrics(v.img0.tensor(&device), v.img1.tensor(&device)).unwrap();
    let psnr: Vec<f64> = metrics.iter().map(|m| m.psnr).collect();
    let ssim: Vec<f64> = metrics.iter().map(|m| m.ssim).collect();
    assert_scalars("image_metrics.psnr", &psnr, &output("psnr").values, 1e-6);
    assert_scalars("image_metrics.ssim", &ssim, &output("ssim").values, 1e-6);
}

fn lpips_alex() -> &'static Lpips {
    static LPIPS: OnceLock<Lpips> = OnceLock::new();
    LPIPS.get_or_init(|| {
        let path = metrics_dir().join("lpips_alex.safetensors");
        Lpips::load(LpipsKind::Alex, &path, &path, &Device::flex()).expect("loading LPIPS-Alex")
    })
}

fn images(device: &Device) -> (Tensor<4>, Tensor<4>) {
    (vectors().img0.tensor(device), vectors().img1.tensor(device))
}

fn to_f64(v: Vec<f32>) -> Vec<f64> {
    v.into_iter().map(f64::from).collect()
}

#[test]
fn lpips_alex_eval_matches_lpips_package() {
    let device = Device::flex();
    let (img0, img1) = images(&device);
    let out = lpips_alex().forward(img0, img1, LpipsInput::ZeroOne).unwrap();
    assert_scalars("lpips", &to_f64(values(out.value)), &output("lpips").values, SCALAR_RTOL);
    assert_scalars("lpips_per_layer", &to_f64(values(out.per_layer)), &output("lpips_per_layer").values, SCALAR_RTOL);
}

#[test]
fn lpips_alex_train_style_matches_lpips_package() {
    let device = Device::flex();
    let (img0, img1) = images(&device);
    let got = to_f64(values(lpips_alex().train_style(img0, img1).unwrap()));
    assert_scalars("lpips_train_style", &got, &output("lpips_train_style").values, SCALAR_RTOL);
}

#[test]
fn lpips_alex_features_and_differences_match() {
    let device = Device::flex();
    let (img0, img1) = images(&device);
    let f0 = lpips_alex().normalized_features(img0, LpipsInput::ZeroOne).unwrap();
    let f1 = lpips_alex().normalized_features(img1, LpipsInput::ZeroOne).unwrap();
    for k in 0..5 {
        let n0 = values(f0[k].clone());
        let n1 = values(f1[k].clone());
        let diff: Vec<f32> = n0.iter().zip(&n1).map(|(a, b)| (a - b) * (a - b)).collect();
        for (name, got) in [("feat_norm0", &n0), ("feat_norm1", &n1), ("diff", &diff)] {
            let reference = output(&format!("lpips.{name}.{k}"));
            assert_eq!(f0[k].dims().to_vec(), reference.shape, "lpips.{name}.{k} shape");
            let err = max_err_rel_to_max(got, &reference.values);
            println!("lpips.{name}.{k}: max error / max |reference| = {err:.2e}");
            assert!(err <= MAP_RTOL, "lpips.{name}.{k}: {err:.3e}");
        }
    }
}

#[test]
fn alexnet_from_torchvision_names_gives_the_same_lpips() {
    let device = Device::flex();
    let dir = metrics_dir();
    let from_torchvision = Lpips::load(
        LpipsKind::Alex,
        dir.join("alexnet_features_torchvision_names.safetensors"),
        dir.join("lpips_alex.safetensors"),
        &device,
    )
    .unwrap();
    let (img0, img1) = images(&device);
    let a = values(from_torchvision.eval(img0.clone(), img1.clone()).unwrap());
    let b = values(lpips_alex().eval(img0, img1).unwrap());
    assert_eq!(a, b, "the two weight files hold the same network");
    assert_scalars("lpips (torchvision names)", &to_f64(a), &output("lpips").values, SCALAR_RTOL);
}

fn gram_loss() -> &'static GramLoss {
    static GRAM: OnceLock<GramLoss> = OnceLock::new();
    GRAM.get_or_init(|| {
        GramLoss::load(metrics_dir().join("vgg16_features.safetensors"), &Device::flex()).expect("loading VGG-16")
    })
}

#[test]
fn gram_matrices_match() {
    let device = Device::flex();
    let (img0, img1) = images(&device);
    for (which, img) in [("img0", img0), ("img1", img1)] {
        let grams = gram_loss().gram_matrices(img).unwrap();
        for (g, layer) in grams.into_iter().zip(["relu1_2", "relu2_2", "relu3_3", "relu4_3"]) {
            let reference = output(&format!("gram.{layer}.{which}"));
            assert_eq!(g.dims().to_vec(), reference.shape);
            let err = max_err_rel_to_max(&values(g), &reference.values);
            println!("gram.{layer}.{which}: max error / max |reference| = {err:.2e}");
            assert!(err <= MAP_RTOL, "gram.{layer}.{which}: {err:.3e}");
        }
    }
}

#[test]
fn gram_loss_matches() {
    let device = Device::flex();
    let (img0, img1) = images(&device);
    let out = gram_loss().forward(img0, img1).unwrap();
    assert_scalars("gram_loss_per_layer", &to_f64(values(out.per_layer)), &output("gram_loss_per_layer").values, 1e-3);
    assert_scalars("gram_loss", &to_f64(values(out.value)), &output("gram_loss").values, 1e-3);
}
