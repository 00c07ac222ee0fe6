//! How long it takes to turn files into network-ready views: decoding plus the release's preprocessing, per view
//! and through the prefetching training stream. Run with `cargo bench -p dggt-data --bench loading`.
//!
//! Reads the real Waymo frame and KITTI sequence from `../shared/real-data` (or `$DGGT_REAL_DATA`) and the bundled
//! synthetic fixture.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use dggt_data::{LoaderOptions, Preprocess, Sampler, SamplerConfig, Scene, open_scene, prepare_view, training_stream};

fn real_data() -> PathBuf {
    dggt_test_data::Shared::RealData.locate()
}

fn time_views(label: &str, scene: &Scene, camera: usize, preprocess: &Preprocess, repeats: usize) {
    let frames = scene.frames.len();
    prepare_view(scene, 0, camera, preprocess).expect("the view loads");
    let started = Instant::now();
    for i in 0..repeats {
        prepare_view(scene, i % frames, camera, preprocess).expect("the view loads");
    }
    let per_view = started.elapsed().as_secs_f64() / repeats as f64;
    println!("{label:<48} {:>8.2} ms/view", per_view * 1e3);
}

fn time_stream(label: &str, scene: Arc<Scene>, preprocess: Preprocess, options: LoaderOptions, steps: usize) {
    let sampler = Sampler::new(SamplerConfig::default(), scene.frames.len(), scene.cameras.len()).expect("sampler");
    let stream = training_stream(scene, sampler, preprocess, 0, 0, options).expect("stream");
    let started = Instant::now();
    let views: usize =
        stream.take(steps).map(|s| s.expect("sample loads")).map(|s| s.inputs.len() + s.targets.len()).sum();
    let elapsed = started.elapsed().as_secs_f64();
    println!("{label:<48} {:>8.1} ms/step {:>8.1} views/s", elapsed / steps as f64 * 1e3, views as f64 / elapsed);
}

fn main() {
    let release = Preprocess::default();
    let waymo = open_scene(&real_data().join("waymo/export_one_frame/000"), None, None).expect("Waymo frame");
    time_views("Waymo FRONT 1920x1280 jpg -> 518x350", &waymo, 0, &release, 20);
    time_views("Waymo SIDE_LEFT 1920x886 jpg -> 518x238", &waymo, 3, &release, 20);
    let kitti = open_scene(&real_data().join("kitti-odometry/sequence_1"), None, None).expect("KITTI sequence");
    time_views("KITTI 1226x370 png -> 518x154", &kitti, 0, &release, 50);

    let fixture = dggt_test_data::fixture("synth-s0");
    let synth = Arc::new(open_scene(&fixture, None, None).expect("fixture"));
    time_views("fixture 160x112 jpg+masks -> 518x364", &synth, 0, &release, 60);
    let kitti = Arc::new(kitti);
    for workers in [1, 2] {
        let options = LoaderOptions { workers, capacity: 2 * workers, decoded_cache_bytes: 0 }; // decode throughput: no cache
        time_stream(&format!("KITTI stream -> 518x154, {workers} worker(s)"), kitti.clone(), release, options, 10);
        time_stream(
            &format!("fixture stream 3 cams -> 518x364, {workers} worker(s)"),
            synth.clone(),
            release,
            options,
            10,
        );
    }
}
