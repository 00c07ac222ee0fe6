//! Numerical stability at the edges: BCE with probabilities exactly 0 and 1 and logits of +-1e4, the
//! lifespan regulariser at 1e6, 1e-6 and 0, LPIPS of identical images (exactly 0) and of constant black
//! images (finite, through the 1e-10 epsilon), all with finite gradients.

use crate::common::{Host, Rng, synthetic_weights, tensor, values, write_safetensors};
use burn::tensor::{Device, Tensor};
use dggt_losses::backbone::{ALEXNET_CONVS, ALEXNET_TAP_CHANNELS, VGG16_CONVS, VGG16_TAP_CHANNELS};
use dggt_losses::lpips::LpipsInput;
use dggt_losses::{Lpips, LpipsKind, bce_probabilities, bce_with_logits, lifespan_l1, opacity_loss};

fn device() -> Device {
    Device::flex().autodiff()
}

fn loss_and_grad<const D: usize>(x: Tensor<D>, f: impl Fn(Tensor<D>) -> Tensor<1>) -> (f32, Vec<f32>) {
    let x = x.require_grad();
    let loss = f(x.clone());
    let grads = loss.backward();
    (values(loss)[0], values(x.grad(&grads).expect("gradient")))
}

fn assert_finite(name: &str, loss: f32, grad: &[f32]) {
    assert!(loss.is_finite(), "{name}: loss {loss}");
    assert!(grad.iter().all(|g| g.is_finite()), "{name}: gradient {grad:?}");
}

#[test]
fn bce_probabilities_at_zero_and_one() {
    let d = device();
    let p = tensor(&[0.0, 1.0, 0.0, 1.0], [4], &d);
    let y = tensor(&[0.0, 1.0, 1.0, 0.0], [4], &d);
    let (loss, grad) = loss_and_grad(p, |p| bce_probabilities(p, y.clone()).unwrap());
    assert_finite("bce_probabilities", loss, &grad);
    // The two wrong ends cost -ln(1e-6) each; the right ones ~1e-6.
    let expected = 2.0 * (1e6f64).ln() / 4.0;
    assert!((loss as f64 - expected).abs() < 1e-3 * expected, "loss {loss}, expected {expected}");
    // Wrong ends are pulled towards the target.
    assert!(grad[2] < 0.0 && grad[3] > 0.0, "{grad:?}");
    let alpha = tensor(&[0.0, 1.0, 1.0, 0.0], [1, 2, 2], &d);
    let sky = tensor(&[1.0, 0.0, 1.0, 0.0], [1, 2, 2], &d);
    let (loss, grad) = loss_and_grad(alpha, |a| opacity_loss(a, sky.clone()).unwrap());
    assert_finite("opacity_loss", loss, &grad);
}

#[test]
fn bce_with_logits_at_large_magnitudes() {
    let d = device();
    let x = tensor(&[1e4, -1e4, 1e4, -1e4], [4], &d);
    let y = tensor(&[1.0, 0.0, 0.0, 1.0], [4], &d);
    let (loss, grad) = loss_and_grad(x, |x| bce_with_logits(x, y.clone()).unwrap());
    assert_finite("bce_with_logits", loss, &grad);
    assert!((loss - 5e3).abs() < 1.0, "two wrong ends of 1e4 each over 4: {loss}");
    let expected = [0.0, 0.0, 0.25, -0.25];
    for (g, e) in grad.iter().zip(expected) {
        assert!((g - e).abs() < 1e-6, "{grad:?}");
    }
}

#[test]
fn lifespan_at_extremes() {
    let d = device();
    let (loss, grad) = loss_and_grad(tensor(&[1e6, 1e6], [2], &d), |s| lifespan_l1(s).unwrap());
    assert_finite("lifespan 1e6", loss, &grad);
    assert!((loss - 1e-6).abs() < 1e-12, "{loss}");
    let (loss, grad) = loss_and_grad(tensor(&[1e-6, 1.0], [2], &d), |s| lifespan_l1(s).unwrap());
    assert_finite("lifespan 1e-6", loss, &grad);
    assert!((loss as f64 - (1e6 + 1.0) / 2.0).abs() < 1.0, "{loss}");
    assert!(grad[0] < 0.0, "a short lifespan is pushed longer: {grad:?}");
    let (loss, grad) = loss_and_grad(tensor(&[0.0, 1e-30], [2], &d), |s| lifespan_l1(s).unwrap());
    assert_finite("lifespan 0", loss, &grad);
    assert!((loss as f64 - 1e6).abs() < 1.0, "clamped at 1e-6: {loss}");
}

fn lpips_nets(dir: &std::path::Path) -> Vec<(&'static str, Lpips, usize)> {
    let alex = dir.join("alex.safetensors");
    write_safetensors(&alex, &synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 31));
    let vgg = dir.join("vgg.safetensors");
    write_safetensors(&vgg, &synthetic_weights(&VGG16_CONVS, Some(&VGG16_TAP_CHANNELS), 32));
    vec![
        ("alex", Lpips::load(LpipsKind::Alex, &alex, &alex, &device()).unwrap(), 32),
        ("vgg", Lpips::load(LpipsKind::Vgg, &vgg, &vgg, &device()).unwrap(), 16),
    ]
}

#[test]
fn lpips_of_identical_images_is_zero_with_finite_gradient() {
    let dir = tempfile::tempdir().unwrap();
    for (name, lpips, size) in lpips_nets(dir.path()) {
        let mut rng = Rng::new(33);
        let image = Host::new(vec![2, size, size, 3], rng.ranges(2 * size * size * 3, 0.0, 1.0));
        for input in [LpipsInput::ZeroOne, LpipsInput::Unscaled] {
            let (loss, grad) = loss_and_grad(image.tensor::<4>(&device()), |x| {
                lpips.forward(x, image.tensor(&device()), input).unwrap().value.sum()
            });
            assert_finite(name, loss, &grad);
            assert_eq!(loss, 0.0, "{name} {input:?}: LPIPS of identical images");
            assert!(grad.iter().all(|g| *g == 0.0), "{name}: zero gradient at the minimum");
        }
    }
}

#[test]
fn lpips_of_black_images_is_finite() {
    let dir = tempfile::tempdir().unwrap();
    for (name, lpips, size) in lpips_nets(dir.path()) {
        let n = size * size * 3;
        let black = Host::new(vec![1, size, size, 3], vec![0.0; n]);
        let grey = Host::new(vec![1, size, size, 3], vec![0.5; n]);
        for input in [LpipsInput::ZeroOne, LpipsInput::Unscaled] {
            for other in [&black, &grey] {
                let (loss, grad) = loss_and_grad(black.tensor::<4>(&device()), |x| {
                    lpips.forward(x, other.tensor(&device()), input).unwrap().value.sum()
                });
                assert_finite(name, loss, &grad);
                println!("{name} {input:?} black vs {}: {loss}", other.values[0]);
            }
        }
    }
}

#[test]
fn lpips_gradient_is_finite_where_taps_vanish() {
    // A backbone whose biases are very negative: every tap is exactly zero for a black image, so the
    // channel norm is 0 and only the 1e-10 / 1e-20 epsilons keep values and gradients finite.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dead.safetensors");
    let mut weights = synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 34);
    for (name, t) in weights.iter_mut() {
        if name.ends_with(".bias") {
            t.values.iter_mut().for_each(|v| *v = -100.0);
        }
    }
    write_safetensors(&path, &weights);
    let lpips = Lpips::load(LpipsKind::Alex, &path, &path, &device()).unwrap();
    let black = Host::new(vec![1, 32, 32, 3], vec![0.0; 32 * 32 * 3]);
    let f0 = lpips.normalized_features(black.tensor(&device()), LpipsInput::ZeroOne).unwrap();
    assert!(f0.iter().all(|f| values(f.clone()).iter().all(|v| *v == 0.0)), "all taps vanish");
    let (loss, grad) = loss_and_grad(black.tensor::<4>(&device()), |x| {
        lpips.forward(x, black.tensor(&device()), LpipsInput::ZeroOne).unwrap().value.sum()
    });
    assert_finite("dead taps", loss, &grad);
    assert_eq!(loss, 0.0);
}
