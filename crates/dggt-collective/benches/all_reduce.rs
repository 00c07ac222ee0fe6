//! Throughput of the gradient all-reduce over MPI on one machine: the full-size model's gradient volume summed
//! by two ranks (host buffers, shared-memory transport), bucket by bucket as a training step sums it.
//!
//! `cargo bench -p dggt-collective --features mpi --bench all_reduce` starts itself under
//! `mpirun -np 2`; `DGGT_BENCH_VALUES` sets the volume (default: 1.35e9 values, every parameter of the
//! full-size network, an upper bound of its trainable ones) and `DGGT_BENCH_BUCKET` the bucket (values).
//! One bucket buffer is reused, so the volume passes through the transport without being held in memory.

use std::time::Instant;

use dggt_collective::ProcessGroup;
use dggt_collective::bucket::DEFAULT_BUCKET_VALUES;

fn setting(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse::<f64>().ok()).map_or(default, |v| v as usize)
}

fn main() {
    if std::env::var_os("OMPI_COMM_WORLD_SIZE").is_none() && std::env::var_os("PMI_SIZE").is_none() {
        let program = std::env::current_exe().expect("the bench binary's path");
        let status = dggt_test_data::mpi_launcher(2, program).status().expect("mpirun runs");
        std::process::exit(status.code().unwrap_or(1));
    }
    let group = ProcessGroup::from_environment().expect("joins the MPI world");
    let total = setting("DGGT_BENCH_VALUES", 1_350_000_000);
    let bucket = setting("DGGT_BENCH_BUCKET", DEFAULT_BUCKET_VALUES);
    let mut buffer = vec![1.0f32; bucket];
    let mut times = Vec::new();
    for _ in 0..3 {
        let started = Instant::now();
        let mut left = total;
        while left > 0 {
            let now = left.min(bucket);
            group.all_reduce_sum(&mut buffer[..now]).expect("the sum");
            buffer[..now].fill(1.0);
            left -= now;
        }
        times.push(started.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let median = times[1];
    if group.rank() == 0 {
        let gb = total as f64 * 4.0 / 1e9;
        println!(
            "all-reduce of {gb:.2} GB of f32 gradients over {} ranks in buckets of {} MiB: median {median:.2} s of 3 \
             ({:.2} GB/s per rank)",
            group.size(),
            (bucket * 4) >> 20,
            gb / median
        );
    }
}
