//! The refiner-training configuration: the shipped tiny configuration parses and validates, settings left
//! out take the Difix paper's values, and bad settings are errors naming them.

use std::path::PathBuf;

use dggt_refine_train::RefineTrainConfig;

fn shipped() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/refine-tiny.toml")
}

#[test]
fn the_shipped_tiny_configuration_parses_and_keeps_the_paper_defaults_it_does_not_set() {
    let config = RefineTrainConfig::load(&shipped()).unwrap();
    assert!(config.model.base_dir.is_absolute() && config.model.base_dir.ends_with("difix_tiny_s1/base"));
    assert_eq!(config.optim.lr, 3e-3, "set in the file");
    let optim = config.optim.section();
    assert_eq!((optim.beta1, optim.beta2, optim.weight_decay, optim.epsilon), (0.9, 0.999, 1e-2, 1e-8));
    assert_eq!(optim.clip_grad_norm, Some(1.0));
    assert!(optim.groups.is_empty() && optim.min_lr_ratio == 1.0, "a constant rate, no groups");
    assert_eq!((config.loss.l2, config.loss.lpips, config.loss.gram), (1.0, 1.0, 0.5));
}

#[test]
fn unset_loss_weights_and_rate_are_the_papers_and_bad_settings_name_themselves() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.toml");
    let text = |extra: &str| {
        format!(
            "[model]\nbase_dir = \"b\"\ncheckpoint = \"c.pkl\"\nprompt_tokens = [1, 2]\n\
             [pairs]\nimages = \"i.safetensors\"\ntensors = [\"image\"]\n\
             [loss]\nlpips_weights = \"l.safetensors\"\ngram_vgg = \"v.safetensors\"\n{extra}"
        )
    };
    std::fs::write(&path, text("")).unwrap();
    let config = RefineTrainConfig::load(&path).unwrap();
    assert_eq!((config.loss.l2, config.loss.lpips, config.loss.gram), (1.0, 1.0, 0.5));
    assert_eq!(config.optim.lr, 2e-5);
    assert_eq!(config.loss.lpips_kind, dggt_losses::LpipsKind::Vgg, "the release's LPIPS network");
    assert_eq!(config.model.checkpoint, Some(dir.path().join("c.pkl")), "relative to the file");
    assert_eq!(config.model.lora_rank, 4, "Difix's rank");

    std::fs::write(&path, text("[run]\nbatch = 0\n")).unwrap();
    let error = RefineTrainConfig::load(&path).unwrap_err().to_string();
    assert!(error.contains("run.batch") && error.contains("run.toml"), "{error}");
    std::fs::write(&path, text("[optim]\nlr = 1e-4\nbetas = 3\n")).unwrap();
    let error = RefineTrainConfig::load(&path).unwrap_err().to_string();
    assert!(error.contains("betas"), "{error}");

    // The prompt as text, or none (Difix's through the tokenizer); never two forms at once.
    let as_text = text("").replace("prompt_tokens = [1, 2]", "prompt = \"remove degradation\"");
    std::fs::write(&path, &as_text).unwrap();
    let config = RefineTrainConfig::load(&path).unwrap();
    assert_eq!(config.model.prompt.as_deref(), Some("remove degradation"));
    assert_eq!(config.loss.gram_start_step, 0, "the Gram term from the first step, as the paper");
    std::fs::write(&path, text("").replace("prompt_tokens = [1, 2]\n", "")).unwrap();
    assert!(RefineTrainConfig::load(&path).unwrap().model.prompt.is_none());
    std::fs::write(&path, as_text.replace("[pairs]", "prompt_tokens = [1]\n[pairs]")).unwrap();
    let error = RefineTrainConfig::load(&path).unwrap_err().to_string();
    assert!(error.contains("model.prompt") && error.contains("at most one"), "{error}");
}
