//! Weight loading: both accepted naming schemes, and errors (never panics) for files that lack a tensor or
//! hold one of the wrong shape, naming the file, the tensor and the expected shape.

use crate::common;
use crate::common::{Host, synthetic_weights, values, write_safetensors};
use burn::tensor::Device;
use dggt_losses::backbone::{ALEXNET_CONVS, ALEXNET_TAP_CHANNELS, VGG16_CONVS};
use dggt_losses::{AlexNet, GramLoss, LossError, Lpips, LpipsKind, Vgg16};

fn device() -> Device {
    Device::flex()
}

#[test]
fn missing_tensor_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alex.safetensors");
    let weights: Vec<_> =
        synthetic_weights(&ALEXNET_CONVS, None, 41).into_iter().filter(|(n, _)| n != "features.3.weight").collect();
    write_safetensors(&path, &weights);
    let error = AlexNet::load(&path, &device()).unwrap_err();
    let message = error.to_string();
    println!("{message}");
    match &error {
        LossError::MissingTensor { path: p, name, aliases, expected } => {
            assert_eq!(name, "features.3.weight");
            assert_eq!(aliases, &["net.slice2.3.weight".to_string()]);
            assert_eq!(expected, &[192, 64, 5, 5]);
            assert!(p.ends_with("alex.safetensors"));
        }
        other => panic!("unexpected error {other:?}"),
    }
    assert!(message.contains("features.3.weight") && message.contains("[192, 64, 5, 5]"));
    assert!(message.contains("alex.safetensors"));
}

#[test]
fn wrongly_shaped_tensor_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    let mut weights = synthetic_weights(&VGG16_CONVS[..10], None, 42);
    let bias = weights.iter_mut().find(|(n, _)| n == "features.19.bias").unwrap();
    bias.1 = Host::new(vec![256], vec![0.0; 256]);
    write_safetensors(&path, &weights);
    let error = GramLoss::load(&path, &device()).unwrap_err();
    println!("{error}");
    match &error {
        LossError::ShapeMismatch { name, expected, found, .. } => {
            assert_eq!(name, "features.19.bias");
            assert_eq!(expected, &[512]);
            assert_eq!(found, &[256]);
        }
        other => panic!("unexpected error {other:?}"),
    }
    assert!(error.to_string().contains("features.19.bias"));
}

#[test]
fn missing_linear_weights_and_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alex.safetensors");
    write_safetensors(&path, &synthetic_weights(&ALEXNET_CONVS, None, 43));
    let error = Lpips::load(LpipsKind::Alex, &path, &path, &device()).unwrap_err();
    println!("{error}");
    assert!(matches!(&error, LossError::MissingTensor { name, .. } if name == "lin0.model.1.weight"), "{error:?}");
    let error = AlexNet::load(dir.path().join("absent.safetensors"), &device()).unwrap_err();
    assert!(matches!(error, LossError::WeightsFile { .. }), "{error:?}");
    let other = dir.path().join("weights.bin");
    std::fs::write(&other, b"not weights").unwrap();
    assert!(matches!(AlexNet::load(&other, &device()).unwrap_err(), LossError::WeightsFile { .. }));
    let garbage = dir.path().join("garbage.safetensors");
    std::fs::write(&garbage, b"not weights").unwrap();
    assert!(matches!(AlexNet::load(&garbage, &device()).unwrap_err(), LossError::WeightsFile { .. }));
    let garbage = dir.path().join("garbage.pth");
    std::fs::write(&garbage, b"not weights").unwrap();
    assert!(matches!(AlexNet::load(&garbage, &device()).unwrap_err(), LossError::WeightsFile { .. }));
}

#[test]
fn lpips_names_and_lins_aliases_load_the_same_network() {
    let dir = tempfile::tempdir().unwrap();
    let torchvision = synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 44);
    let lpips_named: Vec<(String, Host)> = torchvision
        .iter()
        .map(|(name, t)| {
            let renamed = if let Some(rest) = name.strip_prefix("features.") {
                let index: usize = rest.split('.').next().unwrap().parse().unwrap();
                let spec = ALEXNET_CONVS.iter().find(|s| s.index == index).unwrap();
                format!("net.slice{}.{rest}", spec.stage)
            } else {
                name.replace("lin", "lins.")
            };
            (renamed, t.clone())
        })
        .collect();
    let (a, b) = (dir.path().join("a.safetensors"), dir.path().join("b.safetensors"));
    write_safetensors(&a, &torchvision);
    write_safetensors(&b, &lpips_named);
    let la = Lpips::load(LpipsKind::Alex, &a, &a, &device()).unwrap();
    let lb = Lpips::load(LpipsKind::Alex, &b, &b, &device()).unwrap();
    let mut rng = common::Rng::new(45);
    let img0 = Host::new(vec![1, 40, 36, 3], rng.ranges(40 * 36 * 3, 0.0, 1.0));
    let img1 = Host::new(vec![1, 40, 36, 3], rng.ranges(40 * 36 * 3, 0.0, 1.0));
    let va = values(la.eval(img0.tensor(&device()), img1.tensor(&device())).unwrap());
    let vb = values(lb.eval(img0.tensor(&device()), img1.tensor(&device())).unwrap());
    assert_eq!(va, vb);
    assert!(va[0] > 0.0);
}

#[test]
fn vgg_stage_count_and_input_size_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg.safetensors");
    write_safetensors(&path, &synthetic_weights(&VGG16_CONVS[..4], None, 46));
    let vgg = Vgg16::load(&path, 2, &device()).unwrap();
    assert_eq!(vgg.stages(), 2);
    assert!(matches!(Vgg16::load(&path, 6, &device()), Err(LossError::InvalidInput(_))));
    assert!(matches!(GramLoss::new(vgg.clone()), Err(LossError::InvalidInput(_))));
    let taps = vgg.taps(Host::new(vec![1, 3, 4, 6], vec![0.5; 72]).tensor(&device())).unwrap();
    assert_eq!(taps.iter().map(|t| t.dims()).collect::<Vec<_>>(), [[1, 64, 4, 6], [1, 128, 2, 3]]);
    assert!(matches!(
        vgg.taps(Host::new(vec![1, 3, 1, 6], vec![0.5; 18]).tensor(&device())),
        Err(LossError::InvalidInput(_))
    ));
}

#[test]
fn pth_files_load_like_safetensors() {
    let dir = tempfile::tempdir().unwrap();
    let device = device();
    // A torchvision-style AlexNet state dict and an lpips-style `alex.pth` with only the linear weights.
    let weights = synthetic_weights(&ALEXNET_CONVS, Some(&ALEXNET_TAP_CHANNELS), 47);
    let (convs, lins): (Vec<_>, Vec<_>) = weights.iter().cloned().partition(|(n, _)| n.starts_with("features."));
    let (backbone_pth, linear_pth) = (dir.path().join("alexnet.pth"), dir.path().join("alex.pth"));
    common::write_pth(&backbone_pth, &convs);
    common::write_pth(&linear_pth, &lins);
    let all = dir.path().join("all.safetensors");
    write_safetensors(&all, &weights);
    let file = dggt_losses::WeightFile::open(&backbone_pth).unwrap();
    assert_eq!(file.shape("features.0.weight"), Some(vec![64, 3, 11, 11]));
    let from_pth = Lpips::load(LpipsKind::Alex, &backbone_pth, &linear_pth, &device).unwrap();
    let from_safetensors = Lpips::load(LpipsKind::Alex, &all, &all, &device).unwrap();
    let mut rng = common::Rng::new(48);
    let img0 = Host::new(vec![2, 33, 35, 3], rng.ranges(2 * 33 * 35 * 3, 0.0, 1.0));
    let img1 = Host::new(vec![2, 33, 35, 3], rng.ranges(2 * 33 * 35 * 3, 0.0, 1.0));
    let a = values(from_pth.eval(img0.tensor(&device), img1.tensor(&device)).unwrap());
    let b = values(from_safetensors.eval(img0.tensor(&device), img1.tensor(&device)).unwrap());
    assert_eq!(a, b);
    // A wrongly shaped tensor in a .pth file is reported like in safetensors.
    let mut bad = convs;
    bad[0].1 = Host::new(vec![64, 3, 3, 3], vec![0.0; 64 * 27]);
    let bad_path = dir.path().join("bad.pth");
    common::write_pth(&bad_path, &bad);
    let error = AlexNet::load(&bad_path, &device).unwrap_err();
    assert!(
        matches!(&error, LossError::ShapeMismatch { name, found, .. } if name == "features.0.weight" && found == &[64, 3, 3, 3]),
        "{error:?}"
    );
}
