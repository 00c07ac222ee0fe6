//! Forward time of the tiny network (the parity vectors' architecture, random weights) on the default CPU
//! backend: `cargo bench -p dggt-model --bench forward`.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use dggt_model::{Dggt, ModelConfig};

fn main() {
    let device = Device::flex();
    let config = ModelConfig::tiny();
    let model = Dggt::new(&config, &device).expect("tiny model builds");
    println!("{:>7} {:>9} {:>12}", "frames", "size", "forward ms");
    for (frames, height, width) in [(3, 56, 70), (8, 56, 70), (4, 350, 518), (12, 350, 518)] {
        let images = Tensor::<5>::random([1, frames, 3, height, width], Distribution::Uniform(0.0, 1.0), &device);
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
