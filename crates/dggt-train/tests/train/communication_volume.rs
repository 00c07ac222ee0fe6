//! The gradients a run over several processes sums every step, for the full-size network: the trainable
//! parameters of the `dggt` preset, built lazily (no weights allocated), trained from scratch (nothing
//! frozen) and fine-tuned as `configs/dggt-finetune.toml` freezes it. The counts and volumes printed here are
//! the ones `docs/DISTRIBUTED.md` plans with.

use burn::tensor::Device;
use dggt_model::Dggt;
use dggt_model::weights::parameters;
use dggt_train::TrainConfig;

/// Parameters of the network built for `config`: all of them, and those of modules `optim.frozen` leaves
/// trainable.
fn counts(config: &TrainConfig) -> (usize, usize) {
    let model = Dggt::new(&config.model.architecture(), &Device::flex()).expect("the preset builds");
    let mut total = 0;
    let mut trainable = 0;
    for parameter in parameters(&model) {
        let values: usize = parameter.shape.iter().product();
        total += values;
        let module = parameter.path.split('.').next().unwrap_or_default();
        if !config.optim.frozen.iter().any(|frozen| frozen == module) {
            trainable += values;
        }
    }
    (total, trainable)
}

#[test]
fn the_full_size_gradients_to_sum_per_step() {
    let fine_tune = TrainConfig::load(&dggt_test_data::repo_root().join("configs/dggt-finetune.toml")).unwrap();
    let mut from_scratch = fine_tune.clone();
    from_scratch.optim.frozen.clear();
    let (total, all_trainable) = counts(&from_scratch);
    let (_, fine_tuned) = counts(&fine_tune);
    assert_eq!(total, all_trainable);
    assert_eq!(total, 1_286_665_447, "the network as built (docs/BENCHMARKS.md)");
    assert!(fine_tuned < total / 2, "fine-tuning freezes the backbone: {fine_tuned} of {total}");
    for (name, count) in [("from scratch", all_trainable), ("fine-tune", fine_tuned)] {
        let mib = count as f64 * 4.0 / (1 << 20) as f64;
        println!("{name}: {count} trainable parameters, {mib:.1} MiB of f32 gradients per step and rank");
    }
}
