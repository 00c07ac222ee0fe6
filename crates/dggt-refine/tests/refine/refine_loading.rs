//! Loading a refiner: the LoRA merge is the LoRA branch, and a checkpoint or model folder that does not fit
//! the network is an error naming the file and the tensor or module.

use std::path::{Path, PathBuf};

use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Distribution, Tensor, TensorData};
use dggt_refine::lora::{LORA_ALPHA, apply_vae_overlay};
use dggt_refine::weights::{HostTensor, NamedTensors, read_safetensors};
use dggt_refine::{RefineError, Refiner};

use crate::common::vectors_dir;

fn random_host(shape: &[usize]) -> HostTensor {
    let data = Tensor::<1>::random([shape.iter().product::<usize>()], Distribution::Normal(0.0, 1.0), &Device::flex())
        .into_data();
    HostTensor { shape: shape.to_vec(), values: data.try_to_vec::<f32>().unwrap(), file: PathBuf::from("test") }
}

fn device_tensor(tensor: &HostTensor) -> Tensor<4> {
    let shape: [usize; 4] = tensor.shape.clone().try_into().unwrap();
    Tensor::from_data(TensorData::new(tensor.values.clone(), shape), &Device::flex())
}

#[test]
fn a_merged_conv_lora_equals_the_base_conv_plus_the_scaled_branch() {
    let rank = 2;
    let (weight, down, up) = (random_host(&[5, 3, 3, 3]), random_host(&[rank, 3, 3, 3]), random_host(&[5, rank, 1, 1]));
    let mut base = NamedTensors::from([("decoder.conv_in.weight".to_string(), weight.clone())]);
    let checkpoint = NamedTensors::from([
        ("decoder.conv_in.lora_A.vae_skip.weight".to_string(), down.clone()),
        ("decoder.conv_in.lora_B.vae_skip.weight".to_string(), up.clone()),
    ]);
    let overlay =
        apply_vae_overlay(&mut base, checkpoint, &["decoder.conv_in".to_string()], rank, Path::new("c.pkl")).unwrap();
    assert_eq!(overlay.merged, vec!["decoder.conv_in".to_string()]);

    let x = Tensor::<4>::random([1, 3, 7, 9], Distribution::Normal(0.0, 1.0), &Device::flex());
    let same = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
    let pointwise = ConvOptions::new([1, 1], [0, 0], [1, 1], 1);
    let merged = conv2d(x.clone(), device_tensor(&base["decoder.conv_in.weight"]), None, same.clone());
    let branch =
        conv2d(conv2d(x.clone(), device_tensor(&down), None, same.clone()), device_tensor(&up), None, pointwise);
    let expected = conv2d(x, device_tensor(&weight), None, same) + branch * (LORA_ALPHA / rank as f32);
    let error: f32 = (merged - expected).abs().max().into_scalar();
    assert!(error < 1e-4, "merged LoRA differs from the branch by {error}");
}

#[test]
fn a_target_without_its_pair_and_a_pair_without_its_target_are_errors_naming_the_module() {
    let mut base = NamedTensors::from([("decoder.conv_out.weight".to_string(), random_host(&[3, 4, 3, 3]))]);
    let targets = ["decoder.conv_out".to_string()];
    let missing = apply_vae_overlay(&mut base.clone(), NamedTensors::new(), &targets, 4, Path::new("c.pkl"));
    let message = missing.unwrap_err().to_string();
    assert!(message.contains("c.pkl") && message.contains("decoder.conv_out"), "{message}");

    let stray = NamedTensors::from([
        ("decoder.conv_out.lora_A.a.weight".to_string(), random_host(&[4, 4, 3, 3])),
        ("decoder.conv_out.lora_B.a.weight".to_string(), random_host(&[3, 4, 1, 1])),
        ("decoder.conv_in.lora_A.a.weight".to_string(), random_host(&[4, 4, 3, 3])),
        ("decoder.conv_in.lora_B.a.weight".to_string(), random_host(&[3, 4, 1, 1])),
    ]);
    let message = apply_vae_overlay(&mut base, stray, &targets, 4, Path::new("c.pkl")).unwrap_err().to_string();
    assert!(message.contains("decoder.conv_in") && message.contains("not in vae_lora_target_modules"), "{message}");
}

#[test]
fn a_lora_pair_of_the_wrong_rank_is_an_error_with_the_shapes() {
    let mut base = NamedTensors::from([("decoder.conv_out.weight".to_string(), random_host(&[3, 4, 3, 3]))]);
    let checkpoint = NamedTensors::from([
        ("decoder.conv_out.lora_A.a.weight".to_string(), random_host(&[2, 4, 3, 3])),
        ("decoder.conv_out.lora_B.a.weight".to_string(), random_host(&[3, 2, 1, 1])),
    ]);
    let targets = ["decoder.conv_out".to_string()];
    let message = apply_vae_overlay(&mut base, checkpoint, &targets, 4, Path::new("c.pkl")).unwrap_err().to_string();
    assert!(message.contains("decoder.conv_out") && message.contains("[2, 4, 3, 3]"), "{message}");
}

/// A copy of the vectors' base folder whose VAE file has `edit` applied to its tensors.
fn edited_base(edit: impl FnOnce(&mut NamedTensors)) -> tempfile::TempDir {
    let base = vectors_dir().join("base");
    let copy = tempfile::tempdir().unwrap();
    for part in ["unet", "text_encoder", "scheduler", "vae"] {
        std::fs::create_dir(copy.path().join(part)).unwrap();
        for entry in std::fs::read_dir(base.join(part)).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), copy.path().join(part).join(entry.file_name())).unwrap();
        }
    }
    let vae_file = copy.path().join("vae/diffusion_pytorch_model.safetensors");
    let mut tensors = read_safetensors(&vae_file).unwrap();
    edit(&mut tensors);
    let bytes: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .into_iter()
        .map(|(name, t)| (name, t.values.iter().flat_map(|v| v.to_le_bytes()).collect(), t.shape))
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = bytes
        .iter()
        .map(|(name, data, shape)| {
            (name.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), data).unwrap())
        })
        .collect();
    safetensors::serialize_to_file(views, None, &vae_file).unwrap();
    copy
}

fn load_error(base: &Path) -> String {
    let checkpoint = vectors_dir().join("model_difix.pkl");
    match Refiner::load(base, &checkpoint, &[0, 1, 2], &Device::flex()) {
        Ok(_) => panic!("the refiner loaded from an edited folder"),
        Err(error) => error.to_string(),
    }
}

#[test]
fn a_missing_base_tensor_is_an_error_naming_it_and_the_file() {
    let base = edited_base(|tensors| {
        tensors.remove("encoder.conv_in.bias");
    });
    let message = load_error(base.path());
    assert!(
        message.contains("encoder.conv_in.bias") && message.contains("diffusion_pytorch_model.safetensors"),
        "{message}"
    );
}

#[test]
fn a_mis_shaped_base_tensor_is_an_error_naming_it_and_both_shapes() {
    let base = edited_base(|tensors| {
        tensors.get_mut("decoder.conv_out.bias").unwrap().shape = vec![1, 3];
    });
    let message = load_error(base.path());
    assert!(
        message.contains("decoder.conv_out.bias") && message.contains("[1, 3]") && message.contains("[3]"),
        "{message}"
    );
}

#[test]
fn a_checkpoint_that_is_not_a_torch_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let checkpoint = dir.path().join("broken.pkl");
    std::fs::write(&checkpoint, b"not a checkpoint").unwrap();
    let error = Refiner::load(&vectors_dir().join("base"), &checkpoint, &[0], &Device::flex()).err().unwrap();
    assert!(matches!(error, RefineError::File { .. }), "{error}");
    assert!(error.to_string().contains("broken.pkl"), "{error}");
}

/// A made-up model folder at the parity model's sizes loads like a real one: the Difix checkpoint applies, no
/// tensor is left unused, the refiner runs, and the written weights have the made-up distribution.
#[test]
fn a_written_made_up_model_folder_loads_with_the_checkpoint() {
    use dggt_refine::random::{RefinerConfigs, write_random_model};
    let vectors = vectors_dir();
    let configs = RefinerConfigs::read(&vectors.join("base")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_random_model(&configs, dir.path(), &Device::flex()).unwrap();
    for file in ["vae/diffusion_pytorch_model.safetensors", "unet/config.json", "text_encoder/model.safetensors"] {
        assert!(dir.path().join(file).is_file(), "{file} not written");
    }
    assert!(dir.path().join("scheduler/scheduler_config.json").is_file());
    let written = read_safetensors(&dir.path().join("unet/diffusion_pytorch_model.safetensors")).unwrap();
    let (refiner, report) =
        Refiner::load(dir.path(), &vectors.join("model_difix.pkl"), &[5, 7, 9], &Device::flex()).unwrap();
    assert!(report.unused.is_empty(), "{:?}", report.unused);
    // This checkpoint holds a full UNet: every written UNet tensor was overlaid, none left over.
    assert_eq!(report.unet_from_base + report.unet_from_checkpoint.len(), written.len());
    let image = Tensor::<4>::random([1, 3, 16, 24], Distribution::Uniform(0.0, 1.0), &Device::flex());
    let out = refiner.refine(image, None, dggt_refine::Latent::PosteriorMean, &mut Default::default()).unwrap();
    assert_eq!(out.dims(), [1, 3, 16, 24]);
    // Matrices and kernels uniform with variance 1 / fan-in, as made up.
    for (name, tensor) in written.iter().filter(|(_, t)| t.shape.len() >= 2) {
        let bound = (3.0 / tensor.shape[1..].iter().product::<usize>() as f32).sqrt();
        let largest = tensor.values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(largest > 0.0 && largest <= bound, "{name}: largest {largest}, bound {bound}");
    }
}

/// A truncated or garbled safetensors file is an error naming the file, not a panic.
#[test]
fn a_truncated_weights_file_is_an_error_naming_it() {
    let vectors = vectors_dir();
    let source = vectors.join("base/vae/diffusion_pytorch_model.safetensors");
    let bytes = std::fs::read(&source).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.safetensors");
    for cut in [4, 64, bytes.len() - 10] {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let message = read_safetensors(&path).unwrap_err().to_string();
        assert!(message.contains("cut.safetensors") && message.contains("not a safetensors file"), "{cut}: {message}");
    }
}
