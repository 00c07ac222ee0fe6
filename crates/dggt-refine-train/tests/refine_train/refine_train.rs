//! Training the refiner on the tiny random model of `shared/parity/difix_tiny_s1` with synthetic pairs made
//! from its two input images, and the VGG-16 / LPIPS (AlexNet) weights of `shared/parity/metrics`:
//! the loss falls and the held-out PSNR rises; a run resumed halfway ends bit-identical to an uninterrupted
//! one; the encoder gets no update; the exported, merged refiner equals the trained, unmerged one; a pair that
//! cannot be read is replaced and counted, and past `pairs.max_bad_pairs` the run stops with a checkpoint.

use std::collections::HashMap;

use burn::module::ParamId;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_refine::Latent;
use dggt_refine_train::RefineTrainer;
use dggt_refine_train::difix_checkpoint::{load_trained_refiner, to_difix_checkpoint, write_difix_checkpoint};
use dggt_refine_train::loss::{LossValue, RefineLoss};
use dggt_refine_train::model::param_values;
use dggt_refine_train::pair::RenderedPair;
use dggt_refine_train::pair_files::write_pairs;
use dggt_refine_train::pairs::{Image, Pair, batch, step_indices};
use dggt_run::Start;
use dggt_run::progress::Visibility;

use crate::common::{device, tiny_config};

fn values_of(trainer: &RefineTrainer) -> HashMap<ParamId, TensorData> {
    param_values(&trainer.model().weights)
}

#[test]
fn the_loss_falls_and_the_held_out_psnr_rises() {
    let out = tempfile::tempdir().unwrap();
    let mut trainer = RefineTrainer::new(tiny_config(out.path(), 20), device(), Start::Fresh).unwrap();
    let before = trainer.validate().unwrap();
    let records: Vec<_> = (0..20).map(|_| trainer.step().unwrap()).collect();
    let after = trainer.validate().unwrap();
    let mean = |r: &[dggt_refine_train::records::StepRecord]| r.iter().map(|r| r.loss).sum::<f64>() / r.len() as f64;
    let (first, last) = (mean(&records[..5]), mean(&records[15..]));
    println!("loss {first:.4} -> {last:.4}; held-out PSNR {:.2} -> {:.2} dB", before.refined_psnr, after.refined_psnr);
    assert!(records.iter().all(|r| r.grad_norm.is_some()), "a step was skipped: {records:?}");
    assert!(last < 0.85 * first, "the loss did not fall: {first} -> {last}");
    assert!(after.refined_psnr > before.refined_psnr + 1.0, "PSNR {before:?} -> {after:?}");
}

/// With `gram_start_step`, the Gram term is absent before that step and weighted in from it on.
#[test]
fn the_gram_term_counts_from_its_start_step() {
    let out = tempfile::tempdir().unwrap();
    let mut section = tiny_config(out.path(), 1).loss;
    section.gram_start_step = 3;
    let loss = RefineLoss::load(&section, &Device::flex()).unwrap();
    let device = Device::flex();
    let image = |seed: u64| {
        let values: Vec<f32> =
            (0..3 * 32 * 32).map(|i| ((i as u64 * 7919 + seed * 104729) % 1000) as f32 / 1000.0).collect();
        Tensor::<4>::from_data(TensorData::new(values, [1, 3, 32, 32]), &device)
    };
    let total = |value: &LossValue| f64::from(value.total.clone().into_scalar::<f32>());
    let before = loss.compute(image(1), image(2), 2).unwrap();
    let from = loss.compute(image(1), image(2), 3).unwrap();
    assert_eq!(before.gram, 0.0);
    assert!((total(&before) - (before.l2 + before.lpips)).abs() < 1e-5, "{}", total(&before));
    assert!(from.gram > 0.0 && (from.l2, from.lpips) == (before.l2, before.lpips));
    let expected = from.l2 + from.lpips + 0.5 * from.gram;
    assert!((total(&from) - expected).abs() < 1e-5 * expected.max(1.0), "{} vs {expected}", total(&from));
}

#[test]
fn a_resumed_run_ends_bit_identical_to_an_uninterrupted_one() {
    let (whole, halves) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mut straight = RefineTrainer::new(tiny_config(whole.path(), 4), device(), Start::Fresh).unwrap();
    let straight_records: Vec<_> = (0..4).map(|_| straight.step().unwrap()).collect();

    let mut first = RefineTrainer::new(tiny_config(halves.path(), 4), device(), Start::Fresh).unwrap();
    let mut records: Vec<_> = (0..2).map(|_| first.step().unwrap()).collect();
    first.save_checkpoint().unwrap();
    drop(first);
    let mut second = RefineTrainer::new(tiny_config(halves.path(), 4), device(), Start::Resume).unwrap();
    assert_eq!(second.state().step, 2);
    records.extend((0..2).map(|_| second.step().unwrap()));

    assert_eq!(records, straight_records, "losses differ");
    let (a, b) = (values_of(&straight), values_of(&second));
    let by_name = |t: &RefineTrainer, values: &HashMap<ParamId, TensorData>| -> Vec<(String, Vec<f32>)> {
        let index = &t.model().index;
        let mut named: Vec<(String, Vec<f32>)> = index
            .unet
            .iter()
            .chain(&index.vae)
            .map(|(name, (id, _))| (name.clone(), values[id].try_to_vec::<f32>().unwrap()))
            .collect();
        for (target, adapter) in &index.adapters {
            named.push((format!("{target}.a"), values[&adapter.a].try_to_vec::<f32>().unwrap()));
            named.push((format!("{target}.b"), values[&adapter.b].try_to_vec::<f32>().unwrap()));
        }
        named
    };
    let (a, b) = (by_name(&straight, &a), by_name(&second, &b));
    assert_eq!(a.len(), b.len());
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{name} differs after resume");
    }
}

#[test]
fn the_encoder_is_frozen_and_the_trained_parts_change() {
    let out = tempfile::tempdir().unwrap();
    let mut trainer = RefineTrainer::new(tiny_config(out.path(), 2), device(), Start::Fresh).unwrap();
    let before = values_of(&trainer);
    let index = trainer.model().index.clone();
    for _ in 0..2 {
        trainer.step().unwrap();
    }
    let after = values_of(&trainer);
    let changed = |id: &ParamId| before[id].try_to_vec::<f32>().unwrap() != after[id].try_to_vec::<f32>().unwrap();
    let vae =
        |prefix: &'static str| index.vae.iter().filter(move |(n, _)| n.starts_with(prefix)).map(|(n, (id, _))| (n, id));
    let encoder: Vec<_> = vae("encoder.").chain(vae("quant_conv")).collect();
    assert!(encoder.len() > 10, "{} encoder tensors", encoder.len());
    for (name, id) in encoder {
        assert!(!changed(id), "{name} was updated");
    }
    // The decoder's base weights stay; its skip convolutions, LoRA factors and the UNet train.
    for target in index.adapters.keys().filter(|t| !t.contains("skip_conv")) {
        assert!(!changed(&index.vae[&format!("{target}.weight")].0), "{target}'s base weight was updated");
    }
    assert!(vae("decoder.skip_conv_").all(|(_, id)| changed(id)), "a skip convolution did not train");
    assert!(index.adapters.values().any(|a| changed(&a.a) && changed(&a.b)), "no LoRA factor trained");
    assert_eq!(index.adapters.len(), 35);
    let unet_changed = index.unet.values().filter(|(id, _)| changed(id)).count();
    assert!(unet_changed * 10 > index.unet.len() * 9, "{unet_changed} of {} UNet tensors trained", index.unet.len());
}

#[test]
fn the_exported_merged_refiner_equals_the_trained_unmerged_one() {
    let out = tempfile::tempdir().unwrap();
    let config = tiny_config(out.path(), 3);
    let mut trainer = RefineTrainer::new(config.clone(), device(), Start::Fresh).unwrap();
    for _ in 0..3 {
        trainer.step().unwrap();
    }
    let held_out = trainer.pairs().held_out(0).unwrap();
    let image = &held_out.render;
    let unmerged = trainer.refine_host(image, None).unwrap();

    let path = out.path().join("refiner.safetensors");
    write_difix_checkpoint(&to_difix_checkpoint(trainer.model()).unwrap(), &path).unwrap();
    let cpu = Device::flex();
    let tokens = {
        let bytes = std::fs::read(config.model.prompt_tokens_file.as_ref().unwrap()).unwrap();
        let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let ids = file.tensor("input_ids").unwrap();
        ids.data().chunks_exact(8).map(|b| i64::from_le_bytes(b.try_into().unwrap())).collect::<Vec<_>>()
    };
    let (refiner, report) = load_trained_refiner(&config.model.base_dir, &path, &tokens, &cpu).unwrap();
    assert_eq!(report.vae.merged.len(), 35);
    assert!(report.unused.is_empty(), "{:?}", report.unused);
    assert_eq!(report.unet_from_base, 0, "the export carries the whole UNet");
    let merged = refiner
        .refine(batch(&[image], &cpu).unwrap(), None, Latent::PosteriorMean, &mut Default::default())
        .unwrap()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let worst = unmerged.iter().zip(&merged).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    println!("max |merged - unmerged| = {worst:e}");
    assert!(worst <= 1e-5, "merged and unmerged refiners differ by {worst}");

    // The reference-view mode alike.
    let first = trainer.pairs().train(0).unwrap();
    let reference = &first.target;
    let unmerged = trainer.refine_host(image, Some(reference)).unwrap();
    let merged = refiner
        .refine(
            batch(&[image], &cpu).unwrap(),
            Some(batch(&[reference], &cpu).unwrap()),
            Latent::PosteriorMean,
            &mut Default::default(),
        )
        .unwrap()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let worst = unmerged.iter().zip(&merged).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst <= 1e-5, "with a reference view, merged and unmerged refiners differ by {worst}");
    let untrained =
        dggt_refine::Refiner::load(&config.model.base_dir, config.model.checkpoint.as_ref().unwrap(), &tokens, &cpu)
            .unwrap()
            .0
            .refine(batch(&[image], &cpu).unwrap(), None, Latent::PosteriorMean, &mut Default::default())
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
    let moved = untrained.iter().zip(&merged).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(moved > 1e-3, "training changed nothing the export carries ({moved})");
}

#[test]
fn bad_checkpoints_and_pair_files_are_errors_naming_the_file_and_the_part() {
    let out = tempfile::tempdir().unwrap();
    let config = tiny_config(out.path(), 1);
    let trainer = RefineTrainer::new(config.clone(), device(), Start::Fresh).unwrap();
    let mut checkpoint = to_difix_checkpoint(trainer.model()).unwrap();
    let target = "decoder.conv_in";
    checkpoint.vae.remove(&format!("{target}.lora_B.vae_skip.weight")).expect("the export names peft's factors");
    let path = out.path().join("broken.safetensors");
    write_difix_checkpoint(&checkpoint, &path).unwrap();
    let mut broken = config.clone();
    broken.model.checkpoint = Some(path);
    let error = RefineTrainer::new(broken, device(), Start::Fresh).err().expect("a missing factor").to_string();
    assert!(error.contains("broken.safetensors") && error.contains(target), "{error}");

    let images = config.pairs.images.unwrap();
    let error = dggt_refine_train::pair_files::PairFiles::open(&images).unwrap_err().to_string();
    assert!(error.contains("inputs.safetensors") && error.contains("views"), "{error}");
}

#[test]
fn a_fresh_start_from_the_base_has_difixs_targets_and_shapes_zero_lora_b_and_trains() {
    use dggt_refine::checkpoint::DifixCheckpoint;
    use dggt_refine_train::fresh::{SKIP_INIT, fresh_checkpoint};
    let out = tempfile::tempdir().unwrap();
    let mut config = tiny_config(out.path(), 2);
    let released = DifixCheckpoint::read(config.model.checkpoint.as_ref().unwrap()).unwrap();
    let fresh = fresh_checkpoint(&config.model.base_dir, 4, 1).unwrap();
    let sorted = |mut names: Vec<String>| {
        names.sort();
        names
    };
    assert_eq!(sorted(fresh.lora_targets.clone()), sorted(released.lora_targets.clone()), "Difix's target rule");
    let shapes = |c: &DifixCheckpoint| c.vae.iter().map(|(n, t)| (n.clone(), t.shape.clone())).collect::<Vec<_>>();
    assert_eq!(shapes(&fresh), shapes(&released), "the released checkpoint's tensors and shapes");
    for (name, tensor) in &fresh.vae {
        if name.contains("lora_B") {
            assert!(tensor.values.iter().all(|&v| v == 0.0), "{name} starts at zero");
        } else if name.contains("skip_conv") && name.ends_with("base_layer.weight") {
            assert!(tensor.values.iter().all(|&v| v == SKIP_INIT), "{name}");
        }
    }

    config.model.checkpoint = None;
    let mut trainer = RefineTrainer::new(config, device(), Start::Fresh).unwrap();
    for _ in 0..2 {
        let record = trainer.step().unwrap();
        assert!(record.loss.is_finite() && record.grad_norm.is_some(), "{record:?}");
    }
}

#[test]
fn an_unreadable_pair_is_replaced_and_counted_and_past_the_limit_the_run_stops_with_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let image = |seed: usize| Image {
        height: 32,
        width: 48,
        values: (0..3 * 32 * 48).map(|i| ((i * 13 + seed * 29) % 101) as f32 / 100.0).collect(),
    };
    let mut pairs: Vec<RenderedPair> = (0..6)
        .map(|k| RenderedPair {
            pair: Pair { render: image(3 * k), target: image(3 * k + 1), reference: Some(image(3 * k + 2)) },
            frame: k,
            camera: 0,
        })
        .collect();
    let mut config = tiny_config(&dir.path().join("lenient"), 2);
    // The pair the first step draws (of the 5 trained on) holds a value outside [0, 1].
    let bad = step_indices(config.run.seed, 0, config.run.batch, 5)[0];
    pairs[bad].pair.target.values[7] = 1.5;
    let file = dir.path().join("pairs.safetensors");
    write_pairs(&pairs, &file).unwrap();
    config.pairs.images = None;
    config.pairs.rendered = Some(file);

    let mut lenient = RefineTrainer::new(config.clone(), device(), Start::Fresh).unwrap();
    let record = lenient.step().expect("the step trains on the next readable pair");
    assert!(record.loss.is_finite() && record.grad_norm.is_some(), "{record:?}");
    assert_eq!(lenient.state().bad_samples, 1);

    config.pairs.max_bad_pairs = 0;
    config.run.out_dir = dir.path().join("strict");
    let mut strict = RefineTrainer::new(config, device(), Start::Fresh).unwrap();
    let error = strict.run(Visibility::Hidden).expect_err("no pair may fail").to_string();
    let named = format!("pair {bad}");
    assert!(
        error.contains("pairs.safetensors") && error.contains("max_bad_pairs") && error.contains(&named),
        "{error}"
    );
    assert!(dir.path().join("strict/checkpoints/latest").exists(), "a checkpoint saved at the failure");
}
