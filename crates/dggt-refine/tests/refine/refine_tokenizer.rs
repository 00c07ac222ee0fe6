//! The CLIP tokenizer read from a model folder's `tokenizer/`: a small vocabulary and merge list written
//! here, whose expected ids are worked out by hand in the comments; and the prompt's fallbacks when a folder
//! has no tokenizer.

use std::path::Path;

use burn::tensor::Device;
use dggt_refine::tokenizer::ClipTokenizer;
use dggt_refine::{DEFAULT_PROMPT, Prompt, Refiner};

use crate::common::vectors_dir;

/// Merges in rank order. `e m` ranks after `r e`, so in `remove` it never applies (`r e` takes the `e`
/// first): a tokenizer that ignored the ranks would produce `r em ...` and fail.
const MERGES: &str = "#version: 0.2
r e
e m
m o
v e</w>
re mo
remo ve</w>
d e
o n</w>
t i
ti on</w>
' s</w>
";

const VOCAB: &str = r#"{"!": 0, "<|startoftext|>": 10, "<|endoftext|>": 11, "remove</w>": 20, "de": 21, "g": 22,
    "r": 23, "a": 24, "d": 25, "tion</w>": 26, ",</w>": 27, "e</w>": 28, "'s</w>": 29}"#;

fn write_tokenizer(dir: &Path, length: usize) {
    let tokenizer = dir.join("tokenizer");
    std::fs::create_dir_all(&tokenizer).unwrap();
    std::fs::write(tokenizer.join("vocab.json"), VOCAB).unwrap();
    std::fs::write(tokenizer.join("merges.txt"), MERGES).unwrap();
    std::fs::write(tokenizer.join("tokenizer_config.json"), format!(r#"{{"model_max_length": {length}}}"#)).unwrap();
    // sd-turbo's (SD 2.x's) tokenizer pads with "!" (id 0), configured as an object.
    std::fs::write(
        tokenizer.join("special_tokens_map.json"),
        r#"{"bos_token": "<|startoftext|>", "eos_token": "<|endoftext|>", "pad_token": {"content": "!"}}"#,
    )
    .unwrap();
}

#[test]
fn the_default_prompt_is_tokenised_by_rank_ordered_merges_and_padded() {
    let dir = tempfile::tempdir().unwrap();
    write_tokenizer(dir.path(), 16);
    let tokenizer = ClipTokenizer::read(&dir.path().join("tokenizer")).unwrap();
    // remove: r e m o v e</w> -> re m o v e</w> -> re mo v e</w> -> re mo ve</w> -> remo ve</w> -> remove</w>.
    // degradation: d e g r a d a t i o n</w> -> de ... -> ... o n</w> -> on</w> -> t i -> ti -> tion</w>:
    // de g r a d a tion</w>.
    let expected = [10, 20, 21, 22, 23, 24, 25, 24, 26, 11, 0, 0, 0, 0, 0, 0];
    assert_eq!(tokenizer.encode(DEFAULT_PROMPT).unwrap(), expected);
    // Case and whitespace are normalised away.
    assert_eq!(tokenizer.encode("  Remove\t\n DEGRADATION ").unwrap(), expected);
    // Punctuation is its own word, a contraction too; `d e` merges only inside a word, not with the suffix:
    // "de's, e" -> d e</w> | ' s</w> -> 's</w> | ,</w> | e</w>.
    assert_eq!(tokenizer.encode("de's, e").unwrap()[..7], [10, 25, 28, 29, 27, 28, 11]);
}

#[test]
fn a_long_prompt_is_cut_to_the_length_keeping_the_end_token() {
    let dir = tempfile::tempdir().unwrap();
    write_tokenizer(dir.path(), 8);
    let tokenizer = ClipTokenizer::read(&dir.path().join("tokenizer")).unwrap();
    let ids = tokenizer.encode(&"remove ".repeat(20)).unwrap();
    assert_eq!(ids, [10, 20, 20, 20, 20, 20, 20, 11]);
}

#[test]
fn a_piece_outside_the_vocabulary_is_an_error_naming_it_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    write_tokenizer(dir.path(), 16);
    let tokenizer = ClipTokenizer::read(&dir.path().join("tokenizer")).unwrap();
    let message = tokenizer.encode("remove zebra").unwrap_err().to_string();
    assert!(message.contains("vocab.json") && message.contains("'z'"), "{message}");
}

#[test]
fn a_folder_without_a_tokenizer_takes_given_ids_and_refuses_text_naming_the_file() {
    let base = vectors_dir().join("base");
    let checkpoint = vectors_dir().join("model_difix.pkl");
    let device = Device::flex();
    let error = Refiner::load_prompt(&base, &checkpoint, &Prompt::default(), &device).err().unwrap().to_string();
    assert!(error.contains("tokenizer/vocab.json"), "{error}");
    let (refiner, _) = Refiner::load_prompt(&base, &checkpoint, &Prompt::Tokens(vec![3, 1, 4]), &device).unwrap();
    assert_eq!(refiner.prompt_embeds().dims()[1], 3);
}
