//! The refiner run on the tiny random model of `shared/parity/difix_tiny_s1`: a sampled latent, an image whose
//! sides are not multiples of 8, reduced precision and batches of frames; and a converted checkpoint that lacks
//! its LoRA settings. (Parity with the reference itself is `dggt-parity`'s `tests/parity/refine_parity.rs`.)

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use dggt_model::safetensors_file::SafetensorsFile;
use dggt_refine::checkpoint::{DifixCheckpoint, SAFETENSORS_FORMAT};
use dggt_refine::weights::{HostTensor, NamedTensors, write_safetensors};
use dggt_refine::{Latent, Refiner, RefinerPrecision, Trace};

use crate::common::vectors_dir;

/// The tensors of a vector file as stored, by name.
fn read_vectors(path: &Path) -> BTreeMap<String, TensorData> {
    SafetensorsFile::open(path).and_then(|mut file| file.read_all_data()).unwrap()
}

/// The largest absolute difference between two tensors of the same size, in `f64` (infinite where one is NaN).
fn max_abs_difference(a: &TensorData, b: &TensorData) -> f64 {
    let values = |data: &TensorData| data.clone().convert::<f32>().try_to_vec::<f32>().unwrap();
    let (a, b) = (values(a), values(b));
    assert_eq!(a.len(), b.len(), "tensors of different sizes");
    let difference = |(x, y): (&f32, &f32)| (f64::from(*x) - f64::from(*y)).abs();
    a.iter().zip(&b).map(difference).fold(0.0, |m, d| if d.is_nan() { f64::INFINITY } else { m.max(d) })
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

fn load_refiner(device: &Device) -> (Refiner, Tensor<4>) {
    let dir = vectors_dir();
    let inputs = read_vectors(&dir.join("inputs.safetensors"));
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
        let difference = max_abs_difference(&first, &other);
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
        let image_error = max_abs_difference(&out, &reference);
        let eps_error = max_abs_difference(&eps, &reference_eps);
        println!("{name}: image_out {image_error:.3e}, unet.eps {eps_error:.3e}");
        assert!(image_error > 0.0, "{name} computed nothing in reduced precision");
        assert!(image_error < bound && eps_error < 2.0 * bound, "{name}: {image_error} / {eps_error}");
    }
    // The VAE's own cast shows: the whole refiner in f16 differs from the UNet alone in f16.
    let image = |precision: RefinerPrecision| refine(&load_refiner(&device).0.with_precision(precision)).0;
    let (unet_only, all) = (image(RefinerPrecision::unet_only(f16)), image(RefinerPrecision::all(f16)));
    assert!(max_abs_difference(&all, &unet_only) > 0.0, "the VAE stayed in f32");
}

/// Frames refined in batches (with references) are the frames refined one by one, and progress counts them.
#[test]
fn frames_refined_in_batches_equal_frames_refined_one_by_one() {
    let (refiner, image) = load_refiner(&Device::flex());
    let frames = Tensor::cat(vec![image.clone(), image.clone().flip([3]), image.flip([2])], 0);
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
        let error = max_abs_difference(&batched.clone().narrow(0, i, 1).into_data(), &single.into_data());
        assert!(error < 1e-5, "frame {i} differs by {error} batched");
    }
    assert!(
        refiner
            .refine_frames(frames.clone(), Some(references.narrow(0, 0, 2)), Latent::PosteriorMean, 2, |_| ())
            .is_err()
    );
    assert!(refiner.refine_frames(frames, None, Latent::PosteriorMean, 0, |_| ()).is_err());
}
