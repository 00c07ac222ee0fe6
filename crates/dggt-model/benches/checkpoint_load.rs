//! Peak memory and time of loading a full-size DGGT checkpoint: `cargo bench --workspace --bench checkpoint_load`.
//!
//! The bench writes a checkpoint of random `f32` values with the release's key names and PyTorch shapes (derived
//! from the full-size network's own parameter list, mapped back through the loader's renames) to
//! `DGGT_BENCH_CHECKPOINT` (default `/tmp/dggt-full-random.safetensors`), streaming one tensor at a time so the
//! writer never holds more than one write buffer; a file of exactly the expected size is reused. The load itself
//! runs in a child process (this binary run again with `DGGT_BENCH_LOAD_CHILD` set) so that the parent's memory
//! does not count: it builds the network (parameters are lazy), loads the file on the CPU backend, and reports the
//! process high-water mark (`VmHWM` of `/proc/self/status`, file-backed mapped pages included) after each step,
//! plus the highest anonymous RSS (`RssAnon`) seen by a 5 ms sampler, which leaves out page-cache pages of the
//! mapped file that the kernel can drop at any time. The generated file is large (about 5.4 GB): delete it after.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use burn::tensor::Device;
use dggt_data::random::SplitMix64;
use dggt_model::weights::{ParameterInfo, load_checkpoint, module_path, parameters};
use dggt_model::{Dggt, ModelConfig};

/// Set in the child process: the checkpoint to load.
const CHILD_ENV: &str = "DGGT_BENCH_LOAD_CHILD";
const DEFAULT_CHECKPOINT: &str = "/tmp/dggt-full-random.safetensors";
const BYTES_PER_VALUE: usize = 4;

/// Module-side spellings of the loader's renames (`weights::KEY_RENAMES`) and the release spellings they come
/// from; every inverted key is checked against `module_path`, so a rename added there without one here fails.
const MODULE_TO_RELEASE: &[(&str, &str)] = &[
    (".pose_ln_modulation.", ".poseLN_modulation.1."),
    (".resize_layers.up4.", ".resize_layers.0."),
    (".resize_layers.up2.", ".resize_layers.1."),
    (".resize_layers.down2.", ".resize_layers.3."),
    (".res_conf_unit1.", ".resConfUnit1."),
    (".res_conf_unit2.", ".resConfUnit2."),
    (".output_conv2.hidden.", ".output_conv2.0."),
    (".output_conv2.out.", ".output_conv2.2."),
];

const NORMALIZATION_CONTAINERS: &[&str] =
    &["Struct:LayerNorm", "Struct:GroupNorm", "Struct:BatchNorm", "Struct:RmsNorm"];

/// One tensor of the checkpoint: release key and PyTorch shape (Linear weights `[out, in]`).
struct ReleaseTensor {
    key: String,
    shape: Vec<usize>,
}

impl ReleaseTensor {
    fn values(&self) -> usize {
        self.shape.iter().product()
    }
}

/// A module parameter whose release key, found by inverting the renames, does not map back to it.
#[derive(Debug, thiserror::Error)]
#[error("{parameter}: inverted key {key} maps to {mapped}, not back")]
struct KeyNotInvertible {
    parameter: String,
    key: String,
    mapped: String,
}

/// The release key and PyTorch shape a module parameter is loaded from: the inverse of the loader's renames and
/// of burn-store's PyTorch adapter (norm `gamma`/`beta` are `weight`/`bias`; Linear weights are transposed).
fn release_tensor(parameter: &ParameterInfo) -> Result<ReleaseTensor, KeyNotInvertible> {
    let is_norm = NORMALIZATION_CONTAINERS.contains(&parameter.container.as_str());
    let pytorch_path = match (is_norm, parameter.path.rsplit_once('.')) {
        (true, Some((stem, "gamma"))) => format!("{stem}.weight"),
        (true, Some((stem, "beta"))) => format!("{stem}.bias"),
        _ => parameter.path.clone(),
    };
    let key =
        MODULE_TO_RELEASE.iter().fold(pytorch_path.clone(), |key, (module, release)| key.replace(module, release));
    let mapped = module_path(&key);
    if mapped != pytorch_path {
        return Err(KeyNotInvertible { parameter: parameter.path.clone(), key, mapped });
    }
    let mut shape = parameter.shape.clone();
    if parameter.container == "Struct:Linear" && key.ends_with(".weight") {
        shape.reverse();
    }
    Ok(ReleaseTensor { key, shape })
}

/// The safetensors header (JSON, padded with spaces to a multiple of 8 bytes) for `tensors` stored back to back
/// as little-endian `f32`, and the total file size.
fn safetensors_header(tensors: &[ReleaseTensor]) -> (Vec<u8>, u64) {
    let mut entries = serde_json::Map::new();
    let mut offset = 0usize;
    for tensor in tensors {
        let end = offset + tensor.values() * BYTES_PER_VALUE;
        entries.insert(
            tensor.key.clone(),
            serde_json::json!({ "dtype": "F32", "shape": tensor.shape, "data_offsets": [offset, end] }),
        );
        offset = end;
    }
    let mut header = serde_json::to_vec(&entries).expect("a JSON map serialises");
    header.resize(header.len().next_multiple_of(8), b' ');
    let total = 8 + header.len() as u64 + offset as u64;
    (header, total)
}

/// Writes the checkpoint with uniform random values in `[-0.05, 0.05)` (SplitMix64), one 4 MiB chunk at a time.
fn write_checkpoint(path: &Path, tensors: &[ReleaseTensor], header: &[u8]) -> std::io::Result<()> {
    const CHUNK_VALUES: usize = 1 << 20;
    let mut out = BufWriter::with_capacity(CHUNK_VALUES * BYTES_PER_VALUE, File::create(path)?);
    out.write_all(&(header.len() as u64).to_le_bytes())?;
    out.write_all(header)?;
    let mut random = SplitMix64::new(0x2545_f491_4f6c_dd1d);
    let mut chunk = Vec::with_capacity(CHUNK_VALUES * BYTES_PER_VALUE);
    for tensor in tensors {
        let mut left = tensor.values();
        while left > 0 {
            let count = left.min(CHUNK_VALUES);
            chunk.clear();
            for _ in 0..count {
                chunk.extend_from_slice(&((random.unit() - 0.5) * 0.1).to_le_bytes());
            }
            out.write_all(&chunk)?;
            left -= count;
        }
    }
    out.into_inner().map_err(|e| e.into_error())?.sync_all()
}

/// A `kB` field of `/proc/self/status` (`VmHWM`, `VmRSS`, `RssAnon`, ...), in bytes.
fn status_bytes(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("reading /proc/self/status");
    status
        .lines()
        .find_map(|line| line.strip_prefix(field)?.strip_prefix(':'))
        .and_then(|rest| rest.trim().strip_suffix("kB")?.trim().parse::<u64>().ok())
        .map(|kib| kib * 1024)
        .unwrap_or_else(|| panic!("no {field} in /proc/self/status"))
}

/// Child process: builds the full-size network, loads `path`, prints `name=value` lines for the parent.
fn load_in_this_process(path: &Path) {
    let peak_anon = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let sampler = {
        let (peak_anon, stop) = (peak_anon.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                peak_anon.fetch_max(status_bytes("RssAnon"), Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(5));
            }
        })
    };
    let started = Instant::now();
    let mut model = Dggt::new(&ModelConfig::dggt(), &Device::flex()).expect("the dggt preset is valid");
    let build_seconds = started.elapsed().as_secs_f64();
    let hwm_after_build = status_bytes("VmHWM");
    let started = Instant::now();
    let report = load_checkpoint(&mut model, path).unwrap_or_else(|e| panic!("loading {}: {e}", path.display()));
    let load_seconds = started.elapsed().as_secs_f64();
    let hwm_after_load = status_bytes("VmHWM");
    stop.store(true, Ordering::Relaxed);
    sampler.join().expect("sampler thread");
    peak_anon.fetch_max(status_bytes("RssAnon"), Ordering::Relaxed);
    let params: usize = parameters(&model).iter().map(|p| p.shape.iter().product::<usize>()).sum();
    println!("params={params}");
    println!("build_seconds={build_seconds}");
    println!("load_seconds={load_seconds}");
    println!("hwm_after_build={hwm_after_build}");
    println!("hwm_after_load={hwm_after_load}");
    println!("peak_anon={}", peak_anon.load(Ordering::Relaxed));
    println!("rss_after_load={}", status_bytes("VmRSS"));
    println!("applied={}", report.applied.len());
    println!("missing={}", report.missing.len());
    println!("unused={}", report.unused.len());
}

/// Decimal gigabytes, the unit checkpoint sizes are quoted in.
fn gb(bytes: f64) -> String {
    format!("{:.2} GB", bytes / 1e9)
}

fn main() {
    if let Some(path) = std::env::var_os(CHILD_ENV) {
        load_in_this_process(Path::new(&path));
        return;
    }
    let path = PathBuf::from(std::env::var_os("DGGT_BENCH_CHECKPOINT").unwrap_or(DEFAULT_CHECKPOINT.into()));
    let model = Dggt::new(&ModelConfig::dggt(), &Device::flex()).expect("the dggt preset is valid");
    let tensors: Vec<ReleaseTensor> = parameters(&model)
        .iter()
        .map(release_tensor)
        .collect::<Result<_, _>>()
        .unwrap_or_else(|e| panic!("mapping parameters to release keys: {e}"));
    drop(model);
    let (header, file_size) = safetensors_header(&tensors);
    let existing = std::fs::metadata(&path).map(|m| m.len()).ok();
    if existing == Some(file_size) {
        println!("reusing {} ({file_size} bytes)", path.display());
    } else {
        let started = Instant::now();
        write_checkpoint(&path, &tensors, &header).unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        println!(
            "wrote {} ({} tensors, {file_size} bytes) in {:.1} s",
            path.display(),
            tensors.len(),
            started.elapsed().as_secs_f64()
        );
    }

    let output = Command::new(std::env::current_exe().expect("path of this bench binary"))
        .env(CHILD_ENV, &path)
        .output()
        .expect("running the load in a child process");
    let stdout = String::from_utf8_lossy(&output.stdout);
    if !output.status.success() {
        panic!(
            "the loading process failed ({}):\n{stdout}\n{}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let values: BTreeMap<&str, f64> = stdout
        .lines()
        .filter_map(|line| line.split_once('='))
        .filter_map(|(name, value)| Some((name, value.parse().ok()?)))
        .collect();
    let value = |name: &str| *values.get(name).unwrap_or_else(|| panic!("the loading process printed no {name}"));
    let size = file_size as f64;
    println!("load report: {} applied, {} missing, {} unused", value("applied"), value("missing"), value("unused"));
    println!(
        "{:>10} {:>14} {:>16} {:>15} {:>11} {:>15} {:>11} {:>8}",
        "file", "params", "peak RSS build", "peak RSS load", "peak/file", "peak anon load", "anon/file", "load s"
    );
    println!(
        "{:>10} {:>14} {:>16} {:>15} {:>11.2} {:>15} {:>11.2} {:>8.1}",
        gb(size),
        value("params"),
        gb(value("hwm_after_build")),
        gb(value("hwm_after_load")),
        value("hwm_after_load") / size,
        gb(value("peak_anon")),
        value("peak_anon") / size,
        value("load_seconds")
    );
    assert!(value("missing") == 0.0 && value("unused") == 0.0, "a complete checkpoint must load with nothing left");
}
