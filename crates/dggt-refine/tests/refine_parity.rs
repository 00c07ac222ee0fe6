//! Parity with the reference refiner (diffusers 0.42.1 / peft 0.21.2, float32) on the tiny random
//! configuration in `shared/parity/difix_tiny_s1`: the prompt embedding, the noise schedule and every stored
//! intermediate of both modes (single view, and with a reference view), each within
//! `5e-5 * max(1, max|ref|)`, on the CPU backend and (feature `wgpu`) on burn's wgpu device; the same from the
//! checkpoint converted to safetensors.
//!
//! The vectors live beside the repository in `shared/parity/difix_tiny_s1` (`$DGGT_PARITY_DIR/difix_tiny_s1`
//! when set; the variable names the shared `parity` folder). Their README describes the computation.

use std::collections::HashMap;
use std::path::Path;

use burn::tensor::{Device, FloatDType, Tensor};
use dggt_refine::checkpoint::{DifixCheckpoint, SAFETENSORS_FORMAT};
use dggt_refine::parity::{Status, compare, read_vectors, run_parity};
use dggt_refine::weights::{HostTensor, NamedTensors, write_safetensors};
use dggt_refine::{Latent, Refiner, RefinerPrecision, Trace};

mod common;

use common::vectors_dir;

/// `checkpoint`: the vectors' `model_difix.pkl` when `None`.
fn both_modes_match_the_reference(device: &Device, checkpoint: Option<&Path>) {
    let dir = vectors_dir();
    let report = run_parity(&dir, checkpoint, device).expect("the refiner loads and runs");
    println!("{report}{}", report.summary());
    assert_eq!(report.load.unet_from_checkpoint.len(), 208, "the checkpoint's full UNet");
    assert_eq!(report.load.unet_from_base, 0);
    assert_eq!(report.load.vae.merged.len(), 35);
    assert_eq!(report.load.vae.replaced.len(), 4, "{:?}", report.load.vae.replaced);
    assert!(report.load.unused.is_empty(), "unused tensors: {:?}", report.load.unused);
    let outputs = read_vectors(&dir.join("outputs.safetensors")).unwrap();
    assert_eq!(report.rows.len(), outputs.len() + 1, "every output and the prompt embedding compared");
    for mode in ["single.", "ref."] {
        let expected = outputs.keys().filter(|name| name.starts_with(mode)).count();
        assert!(expected >= 24, "only {expected} reference tensors of the {mode} mode");
    }
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    assert!(failed.is_empty(), "outside the tolerance: {failed:?}");
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
fn a_converted_checkpoint_without_its_lora_settings_is_an_error_naming_the_key() {
    let out = tempfile::tempdir().unwrap();
    let path = out.path().join("bare.safetensors");
    let tensors = NamedTensors::from([(
        "unet.conv_in.bias".to_string(),
        HostTensor { shape: vec![1], values: vec![0.0], file: path.clone() },
    )]);
    let metadata = HashMap::from([("format".to_string(), SAFETENSORS_FORMAT.to_string())]);
    write_safetensors(&path, &tensors, metadata).unwrap();
    let message = DifixCheckpoint::read(&path).unwrap_err().to_string();
    assert!(message.contains("bare.safetensors") && message.contains("vae_lora_target_modules"), "{message}");
}

#[test]
fn a_perturbed_tensor_fails_the_comparison() {
    let outputs = read_vectors(&vectors_dir().join("outputs.safetensors")).unwrap();
    let reference = &outputs["single.image_out"];
    let mut values = reference.try_to_vec::<f32>().unwrap();
    values[17] += 1e-3;
    let perturbed = burn::tensor::TensorData::new(values, reference.shape().clone());
    assert_eq!(compare("single.image_out", Some(reference), reference).status, Status::Pass);
    assert_eq!(compare("single.image_out", Some(&perturbed), reference).status, Status::Fail);
    assert!(matches!(compare("single.image_out", None, reference).status, Status::Missing(_)));
}

fn load_refiner(device: &Device) -> (Refiner, Tensor<4>) {
    let dir = vectors_dir();
    let inputs = read_vectors(&dir.join("inputs.safetensors")).unwrap();
    let tokens = inputs["input_ids"].try_to_vec::<i64>().unwrap();
    let (refiner, _) = Refiner::load(&dir.join("base"), &dir.join("model_difix.pkl"), &tokens, device).unwrap();
    (refiner, Tensor::from_data(inputs["image"].clone(), device))
}

#[test]
fn a_sampled_latent_is_reproducible_from_its_seed_and_differs_from_the_mean() {
    let (refiner, image) = load_refiner(&Device::flex());
    let run = |latent: Latent| refiner.refine(image.clone(), None, latent, &mut Trace::Off).unwrap().into_data();
    let first = run(Latent::Sampled { seed: 7 });
    assert_eq!(first, run(Latent::Sampled { seed: 7 }), "the same seed gives the same image");
    for other in [run(Latent::PosteriorMean), run(Latent::Sampled { seed: 8 })] {
        let difference = compare("sampled", Some(&first), &other).max_abs.unwrap();
        assert!(difference > 1e-3, "sampling changed the image by only {difference}");
    }
}

#[test]
fn an_image_whose_sides_are_not_multiples_of_8_keeps_its_size() {
    let (refiner, image) = load_refiner(&Device::flex());
    // 29 x 43: padded to 32 x 48 (latent 4 x 6), cropped back.
    let cropped = image.narrow(2, 0, 29).narrow(3, 0, 43);
    let out = refiner.refine(cropped, None, Latent::PosteriorMean, &mut Trace::Off).unwrap();
    assert_eq!(out.dims(), [1, 3, 29, 43]);
    let values = out.into_data().try_to_vec::<f32>().unwrap();
    assert!(values.iter().all(|v| (0.0..=1.0).contains(v)), "outside [0, 1]");
}

/// The UNet alone, then the UNet and the VAE, in f16 and bf16 (attention upcast): the refined image stays close
/// to the f32 one and comes back in f32. Bounds: a few times the types' rounding (2^-11, 2^-8) carried through
/// the networks' depth; the measured errors on this tiny random model are printed.
#[test]
fn reduced_precision_networks_stay_close_to_f32() {
    let device = Device::flex();
    let (refiner, image) = load_refiner(&device);
    let refine = |refiner: &Refiner| {
        let mut trace = Trace::on();
        let out = refiner.refine(image.clone(), None, Latent::PosteriorMean, &mut trace).unwrap().into_data();
        let eps = trace.into_records().into_iter().find(|(name, _)| name == "unet.eps").unwrap().1;
        (out, eps)
    };
    let (reference, reference_eps) = refine(&refiner);
    let (f16, bf16) = (FloatDType::F16, FloatDType::BF16);
    let cases = [
        (RefinerPrecision::unet_only(f16), 1.5e-2),
        (RefinerPrecision::unet_only(bf16), 8e-2),
        (RefinerPrecision::all(f16), 2e-2),
        (RefinerPrecision::all(bf16), 1.2e-1),
    ];
    for (precision, bound) in cases {
        let name = precision.name();
        let (out, eps) = refine(&load_refiner(&device).0.with_precision(precision));
        assert_eq!(out.dtype(), burn::tensor::DType::F32, "{name}: the image comes back in f32");
        let image_error = compare("image_out", Some(&out), &reference).max_abs.unwrap();
        let eps_error = compare("unet.eps", Some(&eps), &reference_eps).max_abs.unwrap();
        println!("{name}: image_out {image_error:.3e}, unet.eps {eps_error:.3e}");
        assert!(image_error > 0.0, "{name} computed nothing in reduced precision");
        assert!(image_error < bound && eps_error < 2.0 * bound, "{name}: {image_error} / {eps_error}");
    }
    // The VAE's own cast shows: the whole refiner in f16 differs from the UNet alone in f16.
    let image = |precision: RefinerPrecision| refine(&load_refiner(&device).0.with_precision(precision)).0;
    let (unet_only, all) = (image(RefinerPrecision::unet_only(f16)), image(RefinerPrecision::all(f16)));
    assert!(compare("image_out", Some(&all), &unet_only).max_abs.unwrap() > 0.0, "the VAE stayed in f32");
}

/// Frames refined in batches (with references) are the frames refined one by one, and progress counts them.
#[test]
fn frames_refined_in_batches_equal_frames_refined_one_by_one() {
    let (refiner, image) = load_refiner(&Device::flex());
    let frames = Tensor::cat(vec![image.clone(), image.clone().flip([3]), image.clone().flip([2])], 0);
    let references = frames.clone().flip([0]);
    let mut done = Vec::new();
    let batched = refiner
        .refine_frames(frames.clone(), Some(references.clone()), Latent::PosteriorMean, 2, |n| done.push(n))
        .unwrap();
    assert_eq!(done, [2, 3]);
    assert_eq!(batched.dims(), frames.dims());
    for i in 0..3 {
        let single = refiner
            .refine(
                frames.clone().narrow(0, i, 1),
                Some(references.clone().narrow(0, i, 1)),
                Latent::PosteriorMean,
                &mut Trace::Off,
            )
            .unwrap();
        let error =
            compare("frame", Some(&batched.clone().narrow(0, i, 1).into_data()), &single.into_data()).max_abs.unwrap();
        assert!(error < 1e-5, "frame {i} differs by {error} batched");
    }
    assert!(
        refiner
            .refine_frames(frames.clone(), Some(references.narrow(0, 0, 2)), Latent::PosteriorMean, 2, |_| ())
            .is_err()
    );
    assert!(refiner.refine_frames(frames, None, Latent::PosteriorMean, 0, |_| ()).is_err());
}
