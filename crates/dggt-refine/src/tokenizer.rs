//! CLIP's byte-level BPE tokenizer, read from a diffusers model folder's `tokenizer/` (`vocab.json`,
//! `merges.txt`, `tokenizer_config.json`, `special_tokens_map.json`), so the refiner's prompt is given as
//! text rather than as token ids.
//!
//! Text is lower-cased, its whitespace runs collapsed to one space and trimmed, then split into words
//! (letter runs, single digits, the contractions `'s 't 're 've 'm 'll 'd`, and runs of other non-space
//! characters). Each word's UTF-8 bytes become printable characters (GPT-2's byte table), its last
//! character carries the end-of-word suffix `</w>`, and adjacent pieces are merged in the order of
//! `merges.txt` (earlier lines first). The result is framed by the start and end tokens and padded with the
//! configured pad token to `model_max_length` ids (longer prompts are cut to fit, the end token kept).
//! Unicode normalisation (NFC) is not applied: prompts are expected in composed form.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use regex::Regex;
use serde_json::Value;

use crate::error::RefineError;

/// The prompt Difix's refiner is trained with.
pub const DEFAULT_PROMPT: &str = "remove degradation";

/// What the refiner's prompt is given as.
#[derive(Debug, Clone, PartialEq)]
pub enum Prompt {
    /// Text, tokenised by the model folder's `tokenizer/`.
    Text(String),
    /// Token ids, used as they are (a folder without a tokenizer, such as the parity vectors').
    Tokens(Vec<i64>),
}

impl Default for Prompt {
    fn default() -> Self {
        Self::Text(DEFAULT_PROMPT.to_string())
    }
}

impl Prompt {
    /// The token ids of the prompt: tokens as given, text through `model_dir/tokenizer/`.
    pub fn token_ids(&self, model_dir: &Path) -> Result<Vec<i64>, RefineError> {
        match self {
            Self::Tokens(ids) => Ok(ids.clone()),
            Self::Text(text) => ClipTokenizer::read(&model_dir.join("tokenizer"))?.encode(text),
        }
    }
}

pub struct ClipTokenizer {
    vocab: HashMap<String, i64>,
    /// Rank of each mergeable pair (lower merges first).
    merges: HashMap<(String, String), usize>,
    byte_chars: [char; 256],
    words: Regex,
    start: i64,
    end: i64,
    pad: i64,
    /// Ids per encoded prompt, padding included.
    length: usize,
    vocab_path: PathBuf,
}

const END_OF_WORD: &str = "</w>";

impl ClipTokenizer {
    /// Reads a tokenizer folder (diffusers' `tokenizer/`).
    pub fn read(dir: &Path) -> Result<Self, RefineError> {
        let vocab_path = dir.join("vocab.json");
        let vocab: HashMap<String, i64> = read_json_file(&vocab_path)?;
        let merges_path = dir.join("merges.txt");
        let merges = read_merges(&merges_path)?;
        let config: Value = read_optional_json(&dir.join("tokenizer_config.json"))?;
        let special: Value = read_optional_json(&dir.join("special_tokens_map.json"))?;
        let token = |key: &str, default: &str| {
            let name = [&special, &config].iter().find_map(|v| token_content(&v[key])).unwrap_or(default.to_string());
            vocab.get(&name).copied().ok_or_else(|| {
                RefineError::file(&vocab_path, format!("the {key} '{name}' of the tokenizer configuration is missing"))
            })
        };
        let (start, end) = (token("bos_token", "<|startoftext|>")?, token("eos_token", "<|endoftext|>")?);
        // CLIP's tokenizer pads with its end token unless the configuration names another pad token.
        let pad = token("pad_token", "<|endoftext|>")?;
        let length = config["model_max_length"].as_u64().map_or(77, |n| n as usize);
        if length < 2 {
            return Err(RefineError::file(&dir.join("tokenizer_config.json"), "model_max_length below 2"));
        }
        let words = Regex::new(r"'s|'t|'re|'ve|'m|'ll|'d|\p{L}+|\p{N}|[^\s\p{L}\p{N}]+").expect("a valid pattern");
        Ok(Self { vocab, merges, byte_chars: byte_chars(), words, start, end, pad, length, vocab_path })
    }

    /// Ids per encoded prompt.
    pub fn length(&self) -> usize {
        self.length
    }

    /// `text` as `length()` ids: start token, the words' pieces, end token, padding.
    pub fn encode(&self, text: &str) -> Result<Vec<i64>, RefineError> {
        let cleaned = text.split_whitespace().collect::<Vec<_>>().join(" ").to_lowercase();
        let mut ids = vec![self.start];
        for word in self.words.find_iter(&cleaned) {
            for piece in self.pieces(word.as_str()) {
                let id = self.vocab.get(&piece).ok_or_else(|| {
                    RefineError::file(&self.vocab_path, format!("no entry for the piece '{piece}' of '{text}'"))
                })?;
                ids.push(*id);
            }
        }
        ids.truncate(self.length - 1);
        ids.push(self.end);
        ids.resize(self.length, self.pad);
        Ok(ids)
    }

    /// The BPE pieces of one word.
    fn pieces(&self, word: &str) -> Vec<String> {
        let mut pieces: Vec<String> = word.bytes().map(|b| self.byte_chars[b as usize].to_string()).collect();
        if let Some(last) = pieces.last_mut() {
            last.push_str(END_OF_WORD);
        }
        loop {
            let best = pieces
                .windows(2)
                .enumerate()
                .filter_map(|(i, pair)| self.merges.get(&(pair[0].clone(), pair[1].clone())).map(|rank| (*rank, i)))
                .min();
            let Some((_, first)) = best else { return pieces };
            let (left, right) = (pieces[first].clone(), pieces[first + 1].clone());
            let mut merged = Vec::with_capacity(pieces.len());
            let mut i = 0;
            while i < pieces.len() {
                if i + 1 < pieces.len() && pieces[i] == left && pieces[i + 1] == right {
                    merged.push(format!("{left}{right}"));
                    i += 2;
                } else {
                    merged.push(pieces[i].clone());
                    i += 1;
                }
            }
            pieces = merged;
        }
    }
}

/// GPT-2's reversible map from bytes to printable characters: printable Latin-1 bytes map to themselves,
/// the others, in byte order, to the characters from U+0100 on.
fn byte_chars() -> [char; 256] {
    let printable = |b: u32| (33..=126).contains(&b) || (161..=172).contains(&b) || (174..=255).contains(&b);
    let mut chars = ['\0'; 256];
    let mut next = 256;
    for b in 0..256u32 {
        chars[b as usize] = if printable(b) {
            char::from_u32(b).expect("Latin-1")
        } else {
            next += 1;
            char::from_u32(next - 1).expect("below the surrogates")
        };
    }
    chars
}

/// `merges.txt`: one `left right` pair a line in merge order; a first line starting `#version` is a header.
fn read_merges(path: &Path) -> Result<HashMap<(String, String), usize>, RefineError> {
    let text = std::fs::read_to_string(path).map_err(|e| RefineError::io(path, e))?;
    let mut merges = HashMap::new();
    for (number, line) in text.lines().enumerate() {
        if line.is_empty() || (number == 0 && line.starts_with("#version")) {
            continue;
        }
        let Some((left, right)) = line.split_once(' ') else {
            return Err(RefineError::file(path, format!("line {}: expected two pieces, got '{line}'", number + 1)));
        };
        let rank = merges.len();
        merges.entry((left.to_string(), right.to_string())).or_insert(rank);
    }
    Ok(merges)
}

fn read_json_file<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, RefineError> {
    let text = std::fs::read_to_string(path).map_err(|e| RefineError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| RefineError::file(path, format!("invalid JSON: {e}")))
}

/// A JSON file's value, `null` when the file does not exist.
fn read_optional_json(path: &Path) -> Result<Value, RefineError> {
    if path.is_file() { read_json_file(path) } else { Ok(Value::Null) }
}

/// A special token as configured: its text, or an object with the text under `content`.
fn token_content(value: &Value) -> Option<String> {
    match value {
        Value::String(text) => Some(text.clone()),
        Value::Object(map) => map.get("content").and_then(Value::as_str).map(str::to_string),
        _ => None,
    }
}
