//! Autodiff gradients of every loss against central finite differences in f32 on small inputs, on
//! `Device::flex().autodiff()`; the perceptual networks on synthetic (seeded He-normal) weights.
//!
//! Element-wise losses are checked coordinate by coordinate (step 1e-3, error <= 1e-3 of the largest
//! gradient entry + 1e-2 relative; seen: <= 5.1e-4 of the largest entry). The network losses (LPIPS-Alex in
//! both input modes, LPIPS-VGG, Gram) are checked along the gradient and along three random directions
//! (step 1e-3 on the most perturbed value), see [`check_directions`] (seen: <= 7.3e-4 along the gradient,
//! <= 1.9e-3 along random directions). The f32 rounding of the losses and ReLU / max-pool switches inside
//! the step limit this accuracy; `gradients_f64.rs` repeats the network checks in f64 at ~1e-10.

use crate::common::{Host, Rng, synthetic_weights, tensor, values, write_safetensors};
use burn::tensor::{Device, Tensor};
use dggt_losses::backbone::{ALEXNET_CONVS, ALEXNET_TAP_CHANNELS, VGG16_CONVS, VGG16_TAP_CHANNELS};
use dggt_losses::lpips::LpipsInput;
use dggt_losses::{
    AlexNet, GramLoss, Lpips, LpipsKind, bce_probabilities, bce_with_logits, l1, l2, lifespan_l1, opacity_loss,
};

fn device() -> Device {
    Device::flex().autodiff()
}

fn scalar(t: Tensor<1>) -> f64 {
    values(t)[0] as f64
}

/// Autodiff gradient of `f` at `x`.
fn gradient<const D: usize>(f: &dyn Fn(Tensor<D>) -> Tensor<1>, x: &Host) -> Vec<f32> {
    let input = x.tensor::<D>(&device()).require_grad();
    let grads = f(input.clone()).backward();
    values(input.grad(&grads).expect("the input has a gradient"))
}

/// Checks every coordinate of the gradient of `f` at `x` against central differences.
fn check_coordinates<const D: usize>(name: &str, f: &dyn Fn(Tensor<D>) -> Tensor<1>, x: &Host) {
    let h = 1e-3f32;
    let analytic = gradient(f, x);
    let scale = analytic.iter().fold(0.0f64, |m, g| m.max(g.abs() as f64));
    assert!(scale > 0.0 && scale.is_finite(), "{name}: gradient {analytic:?}");
    let mut worst = 0.0f64;
    for (i, &autodiff) in analytic.iter().enumerate() {
        let mut plus = x.clone();
        plus.values[i] += h;
        let mut minus = x.clone();
        minus.values[i] -= h;
        let fd = (scalar(f(plus.tensor(&device()))) - scalar(f(minus.tensor(&device())))) / (2.0 * h as f64);
        let err = (fd - autodiff as f64).abs();
        worst = worst.max(err / scale);
        assert!(
            err <= 1e-3 * scale + 1e-2 * (autodiff as f64).abs(),
            "{name}[{i}]: autodiff {autodiff} vs finite difference {fd}"
        );
    }
    println!("{name}: {} coordinates, worst error / max |gradient| = {worst:.2e}", x.values.len());
}

/// Checks the gradient of `f` at `x` along the gradient itself and along `random` random directions `u`
/// (scaled so that the largest entry is 1: a step of `h` on the most perturbed value): the central difference
/// `(f(x + h u) - f(x - h u)) / 2h` against `<grad, u>`.
///
/// Along the gradient the error must stay below [`GRADIENT_DIRECTION_RTOL`] of the directional derivative.
/// Along a random direction the derivative is a sum of terms of both signs that mostly cancel, so the error
/// is measured against the sum of their magnitudes `sum |grad_i u_i|` ([`RANDOM_DIRECTION_RTOL`]).
fn check_directions<const D: usize>(name: &str, f: &dyn Fn(Tensor<D>) -> Tensor<1>, x: &Host, random: usize) {
    let h = 1e-3f32;
    let analytic = gradient(f, x);
    assert!(analytic.iter().all(|g| g.is_finite()), "{name}: non-finite gradient");
    let mut rng = Rng::new(7);
    let mut directions = vec![("gradient".to_string(), analytic.clone())];
    directions.extend((0..random).map(|d| (format!("random {d}"), rng.normals(x.values.len(), 1.0))));
    for (i, (label, u)) in directions.into_iter().enumerate() {
        let largest = u.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let u: Vec<f32> = u.iter().map(|v| v / largest).collect();
        let shifted = |sign: f32| {
            let v = x.values.iter().zip(&u).map(|(a, b)| a + sign * h * b).collect();
            Host::new(x.shape.clone(), v)
        };
        let fd =
            (scalar(f(shifted(1.0).tensor(&device()))) - scalar(f(shifted(-1.0).tensor(&device())))) / (2.0 * h as f64);
        let directional: f64 = analytic.iter().zip(&u).map(|(g, u)| *g as f64 * *u as f64).sum();
        let magnitude: f64 = analytic.iter().zip(&u).map(|(g, u)| (*g as f64 * *u as f64).abs()).sum();
        let (err, rtol) = if i == 0 {
            ((fd - directional).abs() / directional.abs(), GRADIENT_DIRECTION_RTOL)
        } else {
            ((fd - directional).abs() / magnitude, RANDOM_DIRECTION_RTOL)
        };
        println!("{name} along {label}: autodiff {directional:.6e}, finite difference {fd:.6e}, error {err:.2e}");
        assert!(err <= rtol, "{name} along {label}: autodiff {directional} vs finite difference {fd} ({err:.2e})");
    }
}

/// Relative error allowed along the gradient (seen: below 1e-3).
const GRADIENT_DIRECTION_RTOL: f64 = 3e-3;
/// Error allowed along random directions, relative to `sum |grad_i u_i|`.
const RANDOM_DIRECTION_RTOL: f64 = 1e-2;

fn random(shape: &[usize], low: f32, high: f32, seed: u64) -> Host {
    let mut rng = Rng::new(seed);
    let n = shape.iter().product();
    Host::new(shape.to_vec(), (0..n).map(|_| low + (high - low) * rng.unit()).collect())
}

#[test]
fn photometric_gradients() {
    let target = random(&[1, 2, 2, 3], 0.0, 1.0, 1);
    let x = random(&[1, 2, 2, 3], 0.0, 1.0, 2);
    let t = target.clone();
    check_coordinates("l2", &|x: Tensor<4>| l2(x, t.tensor(&device())).unwrap(), &x);
    let t = target;
    check_coordinates("l1", &|x: Tensor<4>| l1(x, t.tensor(&device())).unwrap(), &x);
}

#[test]
fn bce_gradients() {
    let targets = random(&[2, 2, 3], 0.0, 1.0, 3);
    let probabilities = random(&[2, 2, 3], 0.05, 0.95, 4);
    let t = targets.clone();
    check_coordinates(
        "bce_probabilities",
        &|p: Tensor<3>| bce_probabilities(p, t.tensor(&device())).unwrap(),
        &probabilities,
    );
    let sky = Host::new(vec![2, 2, 3], targets.values.iter().map(|v| (*v > 0.5) as u8 as f32).collect());
    check_coordinates("opacity_loss", &|p: Tensor<3>| opacity_loss(p, sky.tensor(&device())).unwrap(), &probabilities);
    let logits = random(&[2, 2, 3], -4.0, 4.0, 5);
    let t = targets;
    check_coordinates("bce_with_logits", &|x: Tensor<3>| bce_with_logits(x, t.tensor(&device())).unwrap(), &logits);
}

#[test]
fn bce_with_logits_gradient_at_zero_is_sigmoid_minus_target() {
    let device = device();
    let x = tensor(&[0.0, 0.0, 0.0], [3], &device).require_grad();
    let y = tensor(&[0.0, 0.3, 1.0], [3], &device);
    let loss = bce_with_logits(x.clone(), y).unwrap();
    assert!((scalar(loss.clone()) - std::f64::consts::LN_2).abs() < 1e-6);
    let grad = values(x.grad(&loss.backward()).unwrap());
    for (g, y) in grad.iter().zip([0.0, 0.3, 1.0]) {
        assert!((g - (0.5 - y) / 3.0).abs() < 1e-6, "{grad:?}");
    }
}

#[test]
fn lifespan_gradients() {
    let sigma = Host::new(vec![5], vec![0.5, 1.3, 2.0, -0.7, 0.9]);
    check_coordinates("lifespan_l1", &|s: Tensor<1>| lifespan_l1(s).unwrap(), &sigma);
}

fn alex_lpips(dir: &std::path::Path) -> Lpips {
    let path = dir.join("alex.safetensors");
    write_safetensors(&path, &synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 11));
    Lpips::load(LpipsKind::Alex, &path, &path, &device()).unwrap()
}

#[test]
fn lpips_alex_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let lpips = alex_lpips(dir.path());
    let target = random(&[1, 32, 32, 3], 0.0, 1.0, 21);
    let x = random(&[1, 32, 32, 3], 0.0, 1.0, 22);
    for input in [LpipsInput::ZeroOne, LpipsInput::Unscaled] {
        let f = |x: Tensor<4>| lpips.forward(x, target.tensor(&device()), input).unwrap().value.sum();
        check_directions(&format!("lpips alex {input:?}"), &f, &x, 3);
    }
}

#[test]
fn lpips_vgg_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    write_safetensors(&path, &synthetic_weights(&VGG16_CONVS, Some(&VGG16_TAP_CHANNELS), 12));
    let lpips = Lpips::load(LpipsKind::Vgg, &path, &path, &device()).unwrap();
    let target = random(&[1, 16, 16, 3], 0.0, 1.0, 23);
    let x = random(&[1, 16, 16, 3], 0.0, 1.0, 24);
    let f = |x: Tensor<4>| lpips.eval(x, target.tensor(&device())).unwrap().sum();
    check_directions("lpips vgg", &f, &x, 3);
}

#[test]
fn gram_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    let stage4: Vec<_> = VGG16_CONVS.iter().copied().filter(|s| s.stage <= 4).collect();
    write_safetensors(&path, &synthetic_weights(&stage4, None, 13));
    let gram = GramLoss::load(&path, &device()).unwrap();
    let target = random(&[1, 16, 16, 3], 0.0, 1.0, 25);
    let x = random(&[1, 16, 16, 3], 0.0, 1.0, 26);
    let f = |x: Tensor<4>| gram.forward(x, target.tensor(&device())).unwrap().value.sum();
    check_directions("gram", &f, &x, 3);
}

#[test]
fn backbone_weights_get_no_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alex.safetensors");
    write_safetensors(&path, &synthetic_weights(&ALEXNET_CONVS, None, 14));
    let net = AlexNet::load(&path, &device()).unwrap();
    let x = random(&[1, 3, 32, 32], 0.0, 1.0, 27).tensor::<4>(&device()).require_grad();
    let taps = net.taps(x.clone()).unwrap();
    let loss = taps.into_iter().map(|t| t.sum()).reduce(|a, b| a + b).unwrap();
    let grads = loss.backward();
    assert!(x.grad(&grads).is_some(), "the input gets a gradient");
    for conv in &net.convs {
        assert!(conv.weight.grad(&grads).is_none(), "features.{} weight is frozen", conv.spec.index);
        assert!(conv.bias.grad(&grads).is_none(), "features.{} bias is frozen", conv.spec.index);
    }
}
