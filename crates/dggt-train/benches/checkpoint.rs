//! Peak memory of writing a training checkpoint of the full-size network with random weights and a full AdamW
//! state, against the size of that model and state: the checkpoint streams one tensor at a time, so the
//! writing should add about one tensor to the resident set, not a copy of the 16 GB.
//!
//! `cargo bench -p dggt-train --bench checkpoint` (needs about 18 GB of memory and 17 GB of disk under
//! `$TMPDIR`; `-- tiny` runs the tiny preset). The high-water mark is reset (`/proc/self/clear_refs`) just before
//! the write, so the peak is the write's own.

use std::time::Instant;

use burn::module::Module;
use burn::tensor::Device;
use dggt_model::{Dggt, ModelConfig};
use dggt_run::OptimSection;
use dggt_run::checkpoint::RunState;
use dggt_train::checkpoint;
use dggt_train::modules::grouped_optimizer;

const GIB: f64 = (1u64 << 30) as f64;

/// A `kB` field of `/proc/self/status`, in bytes.
fn status_bytes(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status (Linux) is readable");
    let line = status.lines().find(|l| l.starts_with(field)).unwrap_or_else(|| panic!("no {field} in status"));
    let kib: u64 = line.split_whitespace().nth(1).and_then(|v| v.parse().ok()).expect("a kB figure");
    kib * 1024
}

/// Resets the process's resident high-water mark to its current resident set.
fn reset_peak() {
    std::fs::write("/proc/self/clear_refs", "5").expect("/proc/self/clear_refs (Linux >= 4.0) is writable");
}

fn folder_bytes(dir: &std::path::Path) -> u64 {
    std::fs::read_dir(dir).unwrap().filter_map(|e| e.ok()?.metadata().ok()).map(|m| m.len()).sum()
}

fn main() {
    let tiny = std::env::args().any(|a| a == "tiny");
    let (name, config) = if tiny { ("tiny", ModelConfig::tiny()) } else { ("full-size (dggt)", ModelConfig::dggt()) };
    let device = Device::flex().autodiff();
    let started = Instant::now();
    let model = Dggt::new(&config, &device).expect("the preset builds");
    let mut optimizer = grouped_optimizer(&OptimSection::default(), &model);
    optimizer.zero_moments(&model);
    let parameters = model.num_params() as f64;
    let state_gib = 3.0 * parameters * 4.0 / GIB;
    let built = started.elapsed().as_secs_f64();
    println!(
        "{name}: {parameters:.0} parameters, model + AdamW moments {state_gib:.2} GiB (f32), built in {built:.0} s"
    );

    let dir = tempfile::tempdir().expect("a temporary folder");
    let state = RunState { step: 1, ..RunState::starting(0, 1) };
    let before = status_bytes("VmRSS");
    reset_peak();
    let started = Instant::now();
    let settings =
        checkpoint::Settings { model: config, preprocess: Default::default(), configured: Default::default() };
    let written = checkpoint::save(dir.path(), checkpoint::Weights::Trained(&model), &settings, &optimizer, &state, 1)
        .expect("the checkpoint writes");
    let seconds = started.elapsed().as_secs_f64();
    let added = status_bytes("VmHWM").saturating_sub(before) as f64 / GIB;
    let files = folder_bytes(&written) as f64 / GIB;
    println!("resident before the write   {:>9.2} GiB", before as f64 / GIB);
    println!("added by the write (peak)   {added:>9.3} GiB ({:.2} % of model + state)", 100.0 * added / state_gib);
    println!("written                     {files:>9.2} GiB in {seconds:.1} s ({:.2} GiB/s)", files / seconds);
}
