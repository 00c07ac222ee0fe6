//! LPIPS-VGG, for which there are no reference vectors: on synthetic weights it is 0 for identical images,
//! symmetric, and equal to the LPIPS formula composed here directly from the VGG-16 taps (so a wiring error
//! in the loss, e.g. a wrong tap, scaling or weight order, would show).

use crate::common::{Host, Rng, synthetic_weights, values, write_safetensors};
use burn::tensor::{Device, Tensor, TensorData};
use dggt_losses::backbone::{VGG16_CONVS, VGG16_TAP_CHANNELS};
use dggt_losses::lpips::LpipsInput;
use dggt_losses::{Lpips, LpipsKind, LpipsNet, Vgg16, WeightFile};

fn setup(dir: &std::path::Path) -> (Lpips, Vgg16, Vec<Vec<f32>>) {
    let path = dir.join("vgg_lpips.safetensors");
    let weights = synthetic_weights(&VGG16_CONVS, Some(&VGG16_TAP_CHANNELS), 51);
    write_safetensors(&path, &weights);
    let device = Device::flex();
    let lpips = Lpips::load(LpipsKind::Vgg, &path, &path, &device).unwrap();
    let vgg = Vgg16::load(&path, 5, &device).unwrap();
    let lins = (0..5)
        .map(|k| weights.iter().find(|(n, _)| *n == format!("lin{k}.model.1.weight")).unwrap().1.values.clone())
        .collect();
    (lpips, vgg, lins)
}

fn images(seed: u64, shape: [usize; 4]) -> Host {
    let mut rng = Rng::new(seed);
    Host::new(shape.to_vec(), rng.ranges(shape.iter().product(), 0.0, 1.0))
}

/// LPIPS from the taps, on the host after the network: per tap and pixel, unit-normalise over channels,
/// squared difference, weighted channel sum, mean over pixels, sum over taps.
fn direct_lpips(vgg: &Vgg16, lins: &[Vec<f32>], img0: &Host, img1: &Host, to_minus_one_one: bool) -> Vec<f64> {
    let device = Device::flex();
    let network_input = |img: &Host| -> Tensor<4> {
        let x: Tensor<4> = img.tensor::<4>(&device).permute([0, 3, 1, 2]);
        let x = if to_minus_one_one { x.mul_scalar(2.0).sub_scalar(1.0) } else { x };
        let shift = Tensor::<4>::from_data(TensorData::new(vec![-0.030f32, -0.088, -0.188], [1, 3, 1, 1]), &device);
        let scale = Tensor::<4>::from_data(TensorData::new(vec![0.458f32, 0.448, 0.450], [1, 3, 1, 1]), &device);
        (x - shift) / scale
    };
    let t0 = vgg.taps(network_input(img0)).unwrap();
    let t1 = vgg.taps(network_input(img1)).unwrap();
    let views = img0.shape[0];
    let mut result = vec![0.0f64; views];
    for ((a, b), lin) in t0.into_iter().zip(t1).zip(lins) {
        let [_, c, h, w] = a.dims();
        let (a, b) = (values(a), values(b));
        for (v, total) in result.iter_mut().enumerate() {
            let mut layer = 0.0f64;
            for p in 0..h * w {
                let at = |data: &[f32], ch: usize| data[(v * c + ch) * h * w + p] as f64;
                let norm0 = (0..c).map(|ch| at(&a, ch).powi(2)).sum::<f64>().sqrt() + 1e-10;
                let norm1 = (0..c).map(|ch| at(&b, ch).powi(2)).sum::<f64>().sqrt() + 1e-10;
                layer +=
                    (0..c).map(|ch| lin[ch] as f64 * (at(&a, ch) / norm0 - at(&b, ch) / norm1).powi(2)).sum::<f64>();
            }
            *total += layer / (h * w) as f64;
        }
    }
    result
}

#[test]
fn vgg_lpips_equals_direct_composition() {
    let dir = tempfile::tempdir().unwrap();
    let (lpips, vgg, lins) = setup(dir.path());
    let (img0, img1) = (images(52, [2, 24, 20, 3]), images(53, [2, 24, 20, 3]));
    for (input, scaled) in [(LpipsInput::ZeroOne, true), (LpipsInput::Unscaled, false)] {
        let got =
            values(lpips.forward(img0.tensor(&Device::flex()), img1.tensor(&Device::flex()), input).unwrap().value);
        let expected = direct_lpips(&vgg, &lins, &img0, &img1, scaled);
        for (g, e) in got.iter().zip(&expected) {
            let err = (*g as f64 - e).abs() / e.abs();
            println!("{input:?}: loss {g:.7e}, direct {e:.7e}, relative {err:.2e}");
            assert!(err < 1e-5, "{input:?}: {g} vs {e}");
        }
    }
}

#[test]
fn vgg_lpips_is_zero_for_identical_images_and_symmetric() {
    let dir = tempfile::tempdir().unwrap();
    let (lpips, ..) = setup(dir.path());
    let device = Device::flex();
    let (img0, img1) = (images(54, [3, 16, 16, 3]), images(55, [3, 16, 16, 3]));
    let same = values(lpips.eval(img0.tensor(&device), img0.tensor(&device)).unwrap());
    assert_eq!(same, vec![0.0; 3]);
    let ab = lpips.forward(img0.tensor(&device), img1.tensor(&device), LpipsInput::ZeroOne).unwrap();
    let ba = lpips.forward(img1.tensor(&device), img0.tensor(&device), LpipsInput::ZeroOne).unwrap();
    assert_eq!(values(ab.value.clone()), values(ba.value));
    assert_eq!(values(ab.per_layer.clone()), values(ba.per_layer));
    let value = values(ab.value);
    let per_layer = values(ab.per_layer);
    for v in 0..3 {
        assert!(value[v] > 0.0);
        let sum: f32 = per_layer[v * 5..(v + 1) * 5].iter().sum();
        assert!((sum - value[v]).abs() <= 1e-6 * value[v], "per-layer values sum to the total");
    }
}

#[test]
fn vgg_lpips_from_separate_backbone_and_linear_files() {
    let dir = tempfile::tempdir().unwrap();
    let (lpips, ..) = setup(dir.path());
    let weights = WeightFile::open(dir.path().join("vgg_lpips.safetensors")).unwrap();
    let device = Device::flex();
    let rebuilt =
        Lpips::from_file(LpipsNet::Vgg(Vgg16::from_file(&weights, 5, &device).unwrap()), &weights, &device).unwrap();
    let (img0, img1) = (images(56, [1, 16, 32, 3]), images(57, [1, 16, 32, 3]));
    assert_eq!(
        values(lpips.eval(img0.tensor(&device), img1.tensor(&device)).unwrap()),
        values(rebuilt.eval(img0.tensor(&device), img1.tensor(&device)).unwrap())
    );
    let small = images(58, [1, 8, 16, 3]);
    assert!(lpips.eval(small.tensor(&device), small.tensor(&device)).is_err(), "VGG LPIPS needs 16x16 inputs");
}
