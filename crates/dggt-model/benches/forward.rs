//! Forward time of the network with random weights on the default CPU backend.
//!
//! `cargo bench --workspace --bench forward` runs the tiny network (the parity vectors' architecture): the
//! median of three runs after a warm-up, every head. `DGGT_BENCH_PRESET=dggt` runs the full-size network
//! (1.35B parameters) instead, at `DGGT_BENCH_FRAMES` frames (comma separated, default `4,12`) of 518x350: one
//! run each (a run takes minutes on a few cores), with the heads DGGT uses (`ExtraHeads::NONE`), and the
//! process's peak resident memory after each.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use dggt_model::{Dggt, ExtraHeads, ModelConfig};

/// The process's peak resident set (`VmHWM`), in GiB.
fn peak_rss_gib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("VmHWM:"))?.to_owned();
            line.split_whitespace().nth(1)?.parse::<f64>().ok()
        })
        .map_or(f64::NAN, |kib| kib / (1024.0 * 1024.0))
}

fn images(frames: usize, height: usize, width: usize, device: &Device) -> Tensor<5> {
    Tensor::<5>::random([1, frames, 3, height, width], Distribution::Uniform(0.0, 1.0), device)
}

fn tiny(device: &Device) {
    let model = Dggt::new(&ModelConfig::tiny(), device).expect("tiny model builds");
    println!("{:>7} {:>9} {:>12}", "frames", "size", "forward ms");
    for (frames, height, width) in [(3, 56, 70), (8, 56, 70), (4, 350, 518), (12, 350, 518)] {
        let images = images(frames, height, width, device);
        // Warm-up, then the median of three runs; reading the depth back waits for the backend.
        let mut times: Vec<f64> = (0..4)
            .map(|_| {
                let started = Instant::now();
                let out = model.forward(images.clone()).expect("forward");
                let _ = out.depth.prediction.into_data();
                started.elapsed().as_secs_f64() * 1e3
            })
            .skip(1)
            .collect();
        times.sort_by(f64::total_cmp);
        println!("{frames:>7} {:>9} {:>12.1}", format!("{width}x{height}"), times[1]);
    }
}

fn full_size(device: &Device) {
    let frames: Vec<usize> = std::env::var("DGGT_BENCH_FRAMES")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![4, 12]);
    let started = Instant::now();
    let model = Dggt::new(&ModelConfig::dggt(), device).expect("full-size model builds");
    let params = burn::module::Module::num_params(&model);
    // Parameters are created lazily: a small warm-up forward draws them all before anything is timed.
    let _ =
        model.forward_with(images(1, 56, 70, device), ExtraHeads::NONE).expect("warm-up").depth.prediction.into_data();
    println!(
        "dggt preset: {params} parameters, built and initialised in {:.1} s, peak RSS {:.2} GiB",
        started.elapsed().as_secs_f64(),
        peak_rss_gib()
    );
    println!("{:>7} {:>9} {:>12} {:>16}", "frames", "size", "forward s", "peak RSS GiB");
    for frames in frames {
        let images = images(frames, 350, 518, device);
        let started = Instant::now();
        let out = model.forward_with(images, ExtraHeads::NONE).expect("forward");
        let _ = out.depth.prediction.into_data();
        let seconds = started.elapsed().as_secs_f64();
        println!("{frames:>7} {:>9} {seconds:>12.1} {:>16.2}", "518x350", peak_rss_gib());
    }
}

fn main() {
    let device = Device::flex();
    match std::env::var("DGGT_BENCH_PRESET").as_deref() {
        Ok("dggt") => full_size(&device),
        Ok("tiny") | Err(_) => tiny(&device),
        Ok(other) => eprintln!("DGGT_BENCH_PRESET={other}: expected tiny or dggt"),
    }
}
