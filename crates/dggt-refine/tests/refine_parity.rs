//! Parity with the reference refiner (diffusers 0.42.1 / peft 0.21.2, float32) on the tiny random
//! configuration in `shared/parity/difix_tiny_s1`: the prompt embedding, the noise schedule and every stored
//! intermediate of both modes (single view, and with a reference view), each within
//! `5e-5 * max(1, max|ref|)`, on the CPU backend and (feature `wgpu`) on burn's wgpu device.
//!
//! The vectors live beside the repository in `shared/parity/difix_tiny_s1` (`$DGGT_PARITY_DIR/difix_tiny_s1`
//! when set; the variable names the shared `parity` folder). Their README describes the computation.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dggt_refine::config::{SchedulerConfig, read_json};
use dggt_refine::scheduler::alphas_cumprod;
use dggt_refine::{Latent, Refiner, Trace};

/// Allowed error relative to `max(1, max|ref|)`.
const TOLERANCE: f64 = 5e-5;

fn vectors_dir() -> PathBuf {
    let root = std::env::var_os("DGGT_PARITY_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/parity"));
    let dir = root.join("difix_tiny_s1");
    assert!(
        dir.join("outputs.safetensors").is_file(),
        "refiner parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

/// A safetensors file's tensors as host data (floats and integers as stored).
fn read_tensors(path: &Path) -> BTreeMap<String, TensorData> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let file = safetensors::SafeTensors::deserialize(&bytes)
        .unwrap_or_else(|e| panic!("{} is not a safetensors file: {e}", path.display()));
    file.tensors()
        .into_iter()
        .map(|(name, view)| {
            let shape = view.shape().to_vec();
            let data = match view.dtype() {
                safetensors::Dtype::F32 => TensorData::new(
                    view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
                    shape,
                ),
                safetensors::Dtype::I64 => TensorData::new(
                    view.data().chunks_exact(8).map(|b| i64::from_le_bytes(b.try_into().unwrap())).collect(),
                    shape,
                ),
                other => panic!("{name} in {}: unexpected dtype {other:?}", path.display()),
            };
            (name, data)
        })
        .collect()
}

/// One compared tensor: its largest error and the bound it must stay within.
struct Comparison {
    name: String,
    max_error: f64,
    bound: f64,
}

fn compare(name: &str, actual: &TensorData, expected: &TensorData) -> Comparison {
    assert_eq!(actual.shape(), expected.shape(), "{name}: shape");
    let actual = actual.try_to_vec::<f32>().unwrap();
    let expected = expected.try_to_vec::<f32>().unwrap();
    let max_ref = expected.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64));
    let max_error = actual.iter().zip(&expected).fold(0.0f64, |m, (a, e)| {
        let error = (*a as f64 - *e as f64).abs();
        if error.is_nan() { f64::INFINITY } else { m.max(error) }
    });
    Comparison { name: name.to_string(), max_error, bound: TOLERANCE * max_ref.max(1.0) }
}

/// Compares every reference tensor under `prefix` with the traced one of the same name; a reference
/// tensor the trace lacks is a failure.
fn compare_mode(prefix: &str, trace: Trace, outputs: &BTreeMap<String, TensorData>) -> Vec<Comparison> {
    let traced: BTreeMap<String, TensorData> = trace.into_records().into_iter().collect();
    let expected: Vec<_> = outputs.iter().filter_map(|(name, data)| Some((name.strip_prefix(prefix)?, data))).collect();
    assert!(expected.len() > 20, "only {} reference tensors under {prefix}", expected.len());
    expected
        .into_iter()
        .map(|(name, reference)| {
            let actual = traced.get(name).unwrap_or_else(|| panic!("{prefix}{name}: not produced by the refiner"));
            compare(&format!("{prefix}{name}"), actual, reference)
        })
        .collect()
}

fn image(inputs: &BTreeMap<String, TensorData>, name: &str, device: &Device) -> Tensor<4> {
    Tensor::from_data(inputs[name].clone(), device)
}

fn run_parity(device: &Device) {
    let dir = vectors_dir();
    let inputs = read_tensors(&dir.join("inputs.safetensors"));
    let outputs = read_tensors(&dir.join("outputs.safetensors"));
    let tokens = inputs["input_ids"].try_to_vec::<i64>().unwrap();
    let timestep = inputs["timestep"].try_to_vec::<i64>().unwrap();
    assert_eq!(timestep, vec![dggt_refine::TIMESTEP as i64]);

    let (refiner, report) =
        Refiner::load(&dir.join("base"), &dir.join("model_difix.pkl"), &tokens, device).expect("the refiner loads");
    assert_eq!(report.unet_from_checkpoint.len(), 208, "the checkpoint's full UNet");
    assert_eq!(report.unet_from_base, 0);
    assert_eq!(report.vae.merged.len(), 35);
    assert_eq!(report.vae.replaced.len(), 4, "{:?}", report.vae.replaced);
    assert!(report.unused.is_empty(), "unused tensors: {:?}", report.unused);

    let mut comparisons =
        vec![compare("prompt_embeds", &refiner.prompt_embeds().clone().into_data(), &inputs["prompt_embeds"])];
    let scheduler_path = dir.join("base/scheduler/scheduler_config.json");
    let scheduler: SchedulerConfig = read_json(&scheduler_path).unwrap();
    let alphas = alphas_cumprod(&scheduler, &scheduler_path).unwrap();
    comparisons.push(compare(
        "sched.alphas_cumprod",
        &TensorData::new(alphas, [1000]),
        &outputs["sched.alphas_cumprod"],
    ));

    let mut trace = Trace::on();
    refiner.refine(image(&inputs, "image", device), None, Latent::PosteriorMean, &mut trace).unwrap();
    comparisons.extend(compare_mode("single.", trace, &outputs));

    let mut trace = Trace::on();
    let reference = Some(image(&inputs, "ref_image", device));
    refiner.refine(image(&inputs, "image", device), reference, Latent::PosteriorMean, &mut trace).unwrap();
    comparisons.extend(compare_mode("ref.", trace, &outputs));

    let mut failures = Vec::new();
    for c in &comparisons {
        let verdict = if c.max_error <= c.bound { "ok" } else { "FAIL" };
        println!("{:<24} max error {:.3e}  bound {:.1e}  {verdict}", c.name, c.max_error, c.bound);
        if c.max_error > c.bound {
            failures.push(c.name.clone());
        }
    }
    assert!(failures.is_empty(), "outside the tolerance: {failures:?}");
}

#[test]
fn both_modes_match_the_reference_on_the_cpu() {
    run_parity(&Device::flex());
}

#[cfg(feature = "wgpu")]
#[test]
fn both_modes_match_the_reference_on_wgpu() {
    run_parity(&Device::wgpu(burn::tensor::DeviceKind::default()));
}

#[test]
fn a_sampled_latent_is_reproducible_from_its_seed_and_differs_from_the_mean() {
    let device = Device::flex();
    let dir = vectors_dir();
    let inputs = read_tensors(&dir.join("inputs.safetensors"));
    let tokens = inputs["input_ids"].try_to_vec::<i64>().unwrap();
    let (refiner, _) = Refiner::load(&dir.join("base"), &dir.join("model_difix.pkl"), &tokens, &device).unwrap();
    let run = |latent: Latent| {
        refiner.refine(image(&inputs, "image", &device), None, latent, &mut Trace::Off).unwrap().into_data()
    };
    let mean = run(Latent::PosteriorMean);
    let first = run(Latent::Sampled { seed: 7 });
    assert_eq!(first, run(Latent::Sampled { seed: 7 }), "the same seed gives the same image");
    for other in [mean, run(Latent::Sampled { seed: 8 })] {
        let difference = compare("sampled", &first, &other).max_error;
        assert!(difference > 1e-3, "sampling changed the image by only {difference}");
    }
}

#[test]
fn an_image_whose_sides_are_not_multiples_of_8_keeps_its_size() {
    let device = Device::flex();
    let dir = vectors_dir();
    let inputs = read_tensors(&dir.join("inputs.safetensors"));
    let tokens = inputs["input_ids"].try_to_vec::<i64>().unwrap();
    let (refiner, _) = Refiner::load(&dir.join("base"), &dir.join("model_difix.pkl"), &tokens, &device).unwrap();
    // 29 x 43: padded to 32 x 48 (latent 4 x 6), cropped back.
    let cropped = image(&inputs, "image", &device).narrow(2, 0, 29).narrow(3, 0, 43);
    let out = refiner.refine(cropped, None, Latent::PosteriorMean, &mut Trace::Off).unwrap();
    assert_eq!(out.dims(), [1, 3, 29, 43]);
    let values = out.into_data().try_to_vec::<f32>().unwrap();
    assert!(values.iter().all(|v| (0.0..=1.0).contains(v)), "outside [0, 1]");
}
