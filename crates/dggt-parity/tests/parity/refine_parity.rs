//! Parity with the reference refiner (diffusers 0.42.1 / peft 0.21.2, float32) on the tiny random
//! configuration in `shared/parity/difix_tiny_s1`: the prompt embedding, the noise schedule and every stored
//! intermediate of both modes (single view, and with a reference view), each within
//! `5e-5 * max(1, max|ref|)`, on the CPU backend and (feature `wgpu`) on burn's wgpu device; the same from the
//! checkpoint converted to safetensors.
//!
//! The vectors live beside the repository in `shared/parity/difix_tiny_s1` (`$DGGT_PARITY_DIR/difix_tiny_s1`
//! when set; the variable names the shared `parity` folder). Their README describes the computation.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_parity::Status;
use dggt_parity::refiner::{compare, is_refiner_folder, read_vectors, run_parity};
use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::weights::HostTensor;

fn vectors_dir() -> PathBuf {
    let dir = dggt_test_data::parity("difix_tiny_s1");
    assert!(is_refiner_folder(&dir), "{} is not a refiner vector folder", dir.display());
    dir
}

/// `checkpoint`: the vectors' `model_difix.pkl` when `None`.
fn both_modes_match_the_reference(device: &Device, checkpoint: Option<&Path>) {
    let dir = vectors_dir();
    let run = run_parity(&dir, checkpoint, device).expect("the refiner loads and runs");
    let (load, report) = (&run.load, &run.report);
    println!("{report}{}", report.summary());
    assert_eq!(load.unet_from_checkpoint.len(), 208, "the checkpoint's full UNet");
    assert_eq!(load.unet_from_base, 0, "no UNet weight taken from the base model");
    assert_eq!(load.vae.merged.len(), 35, "the VAE's 35 merged tensors");
    assert_eq!(load.vae.replaced.len(), 4, "{:?}", load.vae.replaced);
    assert!(load.unused.is_empty(), "unused tensors: {:?}", load.unused);
    let outputs = read_vectors(&dir.join("outputs.safetensors")).unwrap();
    assert_eq!(report.rows.len(), outputs.len() + 1, "every output and the prompt embedding compared");
    for mode in ["single.", "ref."] {
        let expected = outputs.keys().filter(|name| name.starts_with(mode)).count();
        assert!(expected >= 24, "only {expected} reference tensors of the {mode} mode");
    }
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    assert!(failed.is_empty(), "outside the tolerance: {failed:?}");
    assert!(report.passed(), "the parity report passes");
}

#[test]
fn both_modes_match_the_reference_on_the_cpu() {
    both_modes_match_the_reference(&Device::flex(), None);
}

#[cfg(feature = "wgpu")]
#[test]
fn both_modes_match_the_reference_on_wgpu() {
    both_modes_match_the_reference(&Device::wgpu(burn::tensor::DeviceKind::default()), None);
}

/// The checkpoint converted to safetensors holds the same tensors, bit for bit, and the same LoRA settings,
/// and the refiner loaded from it matches the reference in both modes.
#[test]
fn the_checkpoint_converted_to_safetensors_matches_the_reference() {
    let pickle = DifixCheckpoint::read(&vectors_dir().join("model_difix.pkl")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let converted_path = out.path().join("model_difix.safetensors");
    pickle.write_safetensors(&converted_path).unwrap();
    let converted = DifixCheckpoint::read(&converted_path).unwrap();
    assert_eq!((&converted.lora_targets, converted.lora_rank), (&pickle.lora_targets, pickle.lora_rank));
    assert_eq!(converted.lora_alpha, pickle.lora_alpha);
    for (name, (ours, theirs)) in [("unet", (&converted.unet, &pickle.unet)), ("vae", (&converted.vae, &pickle.vae))] {
        assert_eq!(ours.keys().collect::<Vec<_>>(), theirs.keys().collect::<Vec<_>>(), "{name} tensor names");
        for (key, tensor) in ours {
            let bits = |t: &HostTensor| t.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!((&tensor.shape, bits(tensor)), (&theirs[key].shape, bits(&theirs[key])), "{name}.{key}");
        }
    }
    both_modes_match_the_reference(&Device::flex(), Some(&converted_path));
}

#[test]
fn a_perturbed_tensor_fails_the_comparison() {
    let outputs = read_vectors(&vectors_dir().join("outputs.safetensors")).unwrap();
    let reference = &outputs["single.image_out"];
    let mut values = reference.try_to_vec::<f32>().unwrap();
    values[17] += 1e-3;
    let perturbed = burn::tensor::TensorData::new(values, reference.shape().clone());
    assert_eq!(compare("single.image_out", Some(reference), reference).status, Status::Pass);
    assert_eq!(compare("single.image_out", Some(&perturbed), reference).status, Status::OutOfTolerance);
    assert!(matches!(compare("single.image_out", None, reference).status, Status::NotProduced(_)));
    let other_shape = burn::tensor::TensorData::new(vec![0.0f32; 2], [2]);
    assert_eq!(compare("single.image_out", Some(&other_shape), reference).status, Status::ShapeMismatch(vec![2]));
}
