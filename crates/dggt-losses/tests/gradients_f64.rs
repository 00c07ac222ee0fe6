//! The network losses' gradients against central differences with the flex device's default float type
//! set to f64 (this test binary's process only): without f32 rounding the differences can use a step of
//! 1e-6, small enough that no ReLU or max-pool switches inside it, and agree with autodiff to ~1e-10 (relative
//! to `sum |grad_i u_i|`; asserted: 1e-7) along the gradient and along random directions. Also shows that the losses run in f64 (weights, constants and
//! inputs follow the device's default float type).

mod common;

use std::sync::Once;

use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use common::{Rng, synthetic_weights, write_safetensors};
use dggt_losses::backbone::{ALEXNET_CONVS, ALEXNET_TAP_CHANNELS, VGG16_CONVS, VGG16_TAP_CHANNELS};
use dggt_losses::lpips::LpipsInput;
use dggt_losses::{GramLoss, Lpips, LpipsKind};

fn device() -> Device {
    static CONFIGURE: Once = Once::new();
    CONFIGURE.call_once(|| {
        let mut device = Device::flex();
        device.configure(FloatDType::F64).expect("configuring the flex device for f64");
    });
    Device::flex().autodiff()
}

fn tensor(values: &[f64], shape: [usize; 4]) -> Tensor<4> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), &device())
}

fn scalar(t: Tensor<1>) -> f64 {
    t.into_data().convert::<f64>().try_into_vec::<f64>().unwrap()[0]
}

fn check(name: &str, f: &dyn Fn(Tensor<4>) -> Tensor<1>, shape: [usize; 4], seed: u64) {
    let mut rng = Rng::new(seed);
    let x: Vec<f64> = (0..shape.iter().product()).map(|_| rng.unit() as f64).collect();
    let input = tensor(&x, shape).require_grad();
    let loss = f(input.clone());
    assert_eq!(loss.dtype(), burn::tensor::DType::F64, "{name} runs in f64");
    let grad: Vec<f64> = input.grad(&loss.backward()).unwrap().into_data().try_into_vec::<f64>().unwrap();
    let mut directions = vec![grad.clone()];
    directions.extend((0..2).map(|_| (0..x.len()).map(|_| rng.normal() as f64).collect::<Vec<f64>>()));
    let h = 1e-6;
    for (i, u) in directions.iter().enumerate() {
        let largest = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let u: Vec<f64> = u.iter().map(|v| v / largest).collect();
        let at =
            |sign: f64| scalar(f(tensor(&x.iter().zip(&u).map(|(a, b)| a + sign * h * b).collect::<Vec<_>>(), shape)));
        let fd = (at(1.0) - at(-1.0)) / (2.0 * h);
        let directional: f64 = grad.iter().zip(&u).map(|(g, u)| g * u).sum();
        let magnitude: f64 = grad.iter().zip(&u).map(|(g, u)| (g * u).abs()).sum();
        let err = (fd - directional).abs() / magnitude;
        println!("{name} direction {i}: autodiff {directional:.12e}, finite difference {fd:.12e}, error {err:.2e}");
        assert!(err < 1e-7, "{name} direction {i}: autodiff {directional} vs finite difference {fd}");
    }
}

#[test]
fn lpips_alex_gradient_in_f64() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alex.safetensors");
    write_safetensors(&path, &synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 61));
    let lpips = Lpips::load(LpipsKind::Alex, &path, &path, &device()).unwrap();
    let mut rng = Rng::new(62);
    let target: Vec<f64> = (0..32 * 32 * 3).map(|_| rng.unit() as f64).collect();
    check("lpips alex", &|x| lpips.eval(x, tensor(&target, [1, 32, 32, 3])).unwrap().sum(), [1, 32, 32, 3], 63);
}

#[test]
fn gram_gradient_in_f64() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    let stage4: Vec<_> = VGG16_CONVS.iter().copied().filter(|s| s.stage <= 4).collect();
    write_safetensors(&path, &synthetic_weights(&stage4, None, 64));
    let gram = GramLoss::load(&path, &device()).unwrap();
    let mut rng = Rng::new(65);
    let target: Vec<f64> = (0..16 * 16 * 3).map(|_| rng.unit() as f64).collect();
    check("gram", &|x| gram.forward(x, tensor(&target, [1, 16, 16, 3])).unwrap().value.sum(), [1, 16, 16, 3], 66);
}

#[test]
fn lpips_vgg_gradient_in_f64() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    write_safetensors(&path, &synthetic_weights(&VGG16_CONVS, Some(&VGG16_TAP_CHANNELS), 67));
    let lpips = Lpips::load(LpipsKind::Vgg, &path, &path, &device()).unwrap();
    let mut rng = Rng::new(68);
    let target: Vec<f64> = (0..16 * 16 * 3).map(|_| rng.unit() as f64).collect();
    let f = |x| lpips.forward(x, tensor(&target, [1, 16, 16, 3]), LpipsInput::Unscaled).unwrap().value.sum();
    check("lpips vgg", &f, [1, 16, 16, 3], 69);
}
