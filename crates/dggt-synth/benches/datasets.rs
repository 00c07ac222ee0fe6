//! What a multi-scene training run pays for its data before and during training: indexing a folder of 1,000
//! scene folders (a first build, and the reuse of the cached index), and the throughput of the prefetching
//! dataset stream over one scene of every export variant, with one and two workers. Run with
//! `cargo bench -p dggt-synth --bench datasets`.
//!
//! Every scene is written here by the synthetic generator, so the bench needs no downloaded data. The 1,000
//! folders are hard links to one small scene (copies where the file system refuses links): each is a complete,
//! valid export, and indexing reads only metadata, so the scenes' content does not matter to it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime};

use dggt_data::{
    DatasetIndex, DatasetSampling, DatasetSpec, ExportVariant, LoaderOptions, LogLayout, Preprocess, SamplerConfig,
    SceneMix, dataset_stream,
};
use dggt_synth::{Sweeps, SynthConfig, generate, synthesize, write_export};

/// Scene folders indexed.
const SCENES: usize = 1000;
/// Timed repetitions of each indexing measurement; the median is printed.
const REPEATS: usize = 3;
/// Samples timed per stream, after one untimed sample that lets the workers start.
const SAMPLES: usize = 20;
const SEED: u64 = 7;

/// The scene copied 1,000 times: 20 frames (the sampler's default window) of 3 small cameras.
fn stub_config() -> SynthConfig {
    SynthConfig { seed: 1, frames: 20, cameras: 3, width: 64, height: 48 }
}

/// The scene the streams read: 20 frames of 3 cameras at twice the fixture's resolution.
fn stream_config() -> SynthConfig {
    SynthConfig { seed: 2, frames: 20, cameras: 3, width: 320, height: 224 }
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn seconds<T>(run: impl FnOnce() -> T) -> (T, f64) {
    let started = Instant::now();
    let value = run();
    (value, started.elapsed().as_secs_f64())
}

/// Recreates the folder tree `from` at `to`, every file a hard link (or a copy) of the original.
fn replicate(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap_or_else(|e| panic!("creating {}: {e}", to.display()));
    let entries = std::fs::read_dir(from).unwrap_or_else(|e| panic!("listing {}: {e}", from.display()));
    for entry in entries.map(|e| e.expect("a folder entry")) {
        let (source, target) = (entry.path(), to.join(entry.file_name()));
        if source.is_dir() {
            replicate(&source, &target);
        } else {
            std::fs::hard_link(&source, &target)
                .or_else(|_| std::fs::copy(&source, &target).map(drop))
                .unwrap_or_else(|e| panic!("linking {}: {e}", target.display()));
        }
    }
}

/// Writes one stub scene and `count` replicas of it under `dir/scenes`, which it returns.
fn stub_scenes(dir: &Path, count: usize) -> PathBuf {
    let template = dir.join("template");
    synthesize(&stub_config(), &template, ExportVariant::Waymo, Sweeps::Skip).expect("the stub scene is written");
    let root = dir.join("scenes");
    for i in 0..count {
        replicate(&template, &root.join(format!("{i:04}")));
    }
    root
}

/// The dataset of the scene folders under `root` (or of the one scene at `root`), its layout detected.
fn root_spec(root: &Path) -> DatasetSpec {
    DatasetSpec { root: Some(root.to_owned()), layout: LogLayout::Detect, ..DatasetSpec::default() }
}

/// Fails unless `index` holds `count` scenes and excludes none.
fn check_index(index: &DatasetIndex, count: usize) {
    if let Some(excluded) = index.excluded.first() {
        panic!("{} scene(s) excluded, e.g. {}: {}", index.excluded.len(), excluded.root.display(), excluded.reason);
    }
    assert_eq!(index.scenes.len(), count, "scenes indexed");
}

/// The times of `REPEATS` runs of `run`, each checked to index `scenes` scenes.
fn time_indexing(scenes: usize, run: impl Fn() -> DatasetIndex) -> Vec<f64> {
    let once = || {
        let (index, time) = seconds(&run);
        check_index(&index, scenes);
        time
    };
    (0..REPEATS).map(|_| once()).collect()
}

fn index_row(label: &str, scenes: usize, times: Vec<f64>) {
    let time = median(times);
    println!("{label:<52} {:>9.0} scenes/s {time:>9.4} s", scenes as f64 / time);
}

fn modified(path: &Path) -> SystemTime {
    std::fs::metadata(path).and_then(|m| m.modified()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Times building the index of `root` from the files, then reusing its cache file.
fn bench_index(root: &Path, cache: &Path, scenes: usize) {
    let specs = [root_spec(root)];
    let build = || DatasetIndex::build(&specs, SEED, &|_, _| {}).expect("the index builds");
    index_row(&format!("index {scenes} scene folders, build"), scenes, time_indexing(scenes, build));

    let load = || DatasetIndex::load_or_build(&specs, SEED, cache, &|_, _| {}).expect("the index loads");
    check_index(&load(), scenes);
    let written = modified(cache);
    let loads = time_indexing(scenes, load);
    assert_eq!(modified(cache), written, "load_or_build rebuilt the index instead of reusing {}", cache.display());
    index_row(&format!("index {scenes} scene folders, load_or_build (cached)"), scenes, loads);
}

/// The sampling of the one scene at `root`, which must be read as `layout`.
fn sampling(root: &Path, layout: LogLayout) -> DatasetSampling {
    let index = DatasetIndex::build(&[root_spec(root)], SEED, &|_, _| {}).expect("indexed");
    check_index(&index, 1);
    assert_eq!(index.scenes[0].layout, layout, "layout detected for {}", root.display());
    let mix = SceneMix::new(&index, SEED).expect("a training scene");
    DatasetSampling { index: Arc::new(index), mix, sampler: SamplerConfig::default(), seed: SEED }
}

/// Views per second of the dataset stream over `SAMPLES` samples, once the first one has arrived.
fn views_per_second(sampling: DatasetSampling, workers: usize) -> f64 {
    let options = LoaderOptions { workers, capacity: 2 * workers, decoded_cache_bytes: 0 }; // decode throughput: no cache
    let mut stream = dataset_stream(sampling, Preprocess::default(), 0.., options).expect("stream");
    stream.next().expect("a first sample").expect("the first sample loads");
    let (views, time) = seconds(|| {
        let samples = stream.by_ref().take(SAMPLES).map(|s| s.expect("the sample loads"));
        samples.map(|s| s.inputs.len() + s.targets.len()).sum::<usize>()
    });
    views as f64 / time
}

/// Times the stream over one scene of every export variant.
fn bench_streams(dir: &Path) {
    let config = stream_config();
    let scene = generate(&config).expect("the stream scene generates");
    for variant in ExportVariant::ALL {
        let root = dir.join(variant.name());
        let (_, written) = seconds(|| write_export(&scene, &root, variant, Sweeps::Skip).expect("scene written"));
        eprintln!("{} stream scene written in {written:.1} s", variant.name());
        let sampling = sampling(&root, LogLayout::from(variant));
        for workers in [1, 2] {
            let rate = views_per_second(sampling.clone(), workers);
            let label = format!("stream {} {}x{}, {workers} worker(s)", variant.name(), config.width, config.height);
            println!("{label:<52} {rate:>9.1} views/s {:>8.1} views/s/worker", rate / workers as f64);
        }
    }
}

fn main() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (root, made) = seconds(|| stub_scenes(dir.path(), SCENES));
    eprintln!("{SCENES} stub scene folders written in {made:.1} s");
    bench_index(&root, &dir.path().join("index.json"), SCENES);
    bench_streams(dir.path());
}
