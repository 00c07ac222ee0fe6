//! Training over two MPI ranks on the CPU (`mpirun -np 2 dggt train`, Open MPI or MPICH from the
//! distribution's packages):
//!
//! - two ranks at accumulation 1 train the weights one process at accumulation 2 trains (within 1e-5), end
//!   with the same weights on both ranks (each run checks it: every rank compares its weights' checksum with
//!   rank 0's and the run fails when one differs; rank 0 logs the agreement), and write one set of files:
//!   rank 0's checkpoints and one metrics record per step;
//! - a job whose rank 1 exits mid-run (the `rank-1-exits-at-step-3` failpoint) ends within a minute with a
//!   message naming the failure and no partial checkpoint, and resuming it on two ranks ends with the
//!   weights of the uninterrupted two-rank run, bit for bit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use dggt_run::failpoint::{FAILPOINT_VARIABLE, rank_exit_name};

mod common;

const STEPS: u64 = 4;

/// The small configuration at `accumulation`, checkpointing every second step, written to `dir/NAME.toml`.
fn write_config(dir: &Path, name: &str, accumulation: usize) -> PathBuf {
    let mut config = common::small_config(&dir.join("unused"));
    config.run.steps = STEPS;
    config.run.checkpoint_every = 2;
    config.run.keep_checkpoints = 10;
    config.optim.accumulation = accumulation;
    common::write_config(dir.join(format!("{name}.toml")), &config)
}

/// `dggt train` of `config` into `out`, on `ranks` MPI ranks (as root in a container: any core count, shared
/// memory and loopback transports only) or plainly for one.
fn train(ranks: usize, config: &Path, out: &Path, resume: bool, failpoint: Option<&str>) -> Output {
    let binary = env!("CARGO_BIN_EXE_dggt");
    let mut command = match ranks {
        1 => Command::new(binary),
        _ => dggt_test_data::mpi_launcher(ranks, binary),
    };
    command.args(["train", "--config"]).arg(config).arg("--out").arg(out);
    if resume {
        command.arg("--resume");
    }
    command.env_remove(FAILPOINT_VARIABLE);
    if let Some(name) = failpoint {
        command.env(FAILPOINT_VARIABLE, name);
    }
    command.output().expect("the run starts (mpirun: install openmpi-bin and libopenmpi-dev)")
}

fn text(output: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

fn succeeded(output: &Output) -> String {
    let text = text(output);
    assert!(output.status.success(), "the run failed:\n{text}");
    text
}

/// The checkpoint folders written under `out`, sorted.
fn checkpoint_folders(out: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(out.join("checkpoints"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Every tensor of the checkpoint `out/checkpoints/step-STEP`, by name, as `f32`.
fn weights(out: &Path, step: u64) -> Vec<(String, Vec<f32>)> {
    let dir = out.join("checkpoints").join(format!("step-{step:08}"));
    let reader = burn_pack::Reader::from_file(dir.join("model.bpk")).unwrap();
    let mut tensors: Vec<(String, Vec<f32>)> = reader
        .into_tensors()
        .unwrap()
        .into_iter()
        .map(|t| {
            let (name, _, _, _, bytes) = t.into_parts().unwrap();
            let values = bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
            (name, values)
        })
        .collect();
    tensors.sort_by(|a, b| a.0.cmp(&b.0));
    tensors
}

/// The largest difference between two sets of weights of the same tensors.
fn largest_difference(a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)]) -> f32 {
    assert_eq!(a.len(), b.len(), "the same number of tensors");
    let mut largest = 0.0f32;
    for ((name, x), (other, y)) in a.iter().zip(b) {
        assert_eq!(name, other, "tensors in the same order");
        assert_eq!(x.len(), y.len(), "{name}");
        for (u, v) in x.iter().zip(y) {
            largest = largest.max((u - v).abs());
        }
    }
    largest
}

fn train_records(out: &Path) -> usize {
    std::fs::read_to_string(out.join("metrics.jsonl")).unwrap().matches("\"kind\":\"train\"").count()
}

#[test]
fn two_ranks_train_as_one_process_at_twice_the_accumulation_and_survive_losing_a_rank() {
    let dir = tempfile::tempdir().unwrap();
    let per_rank = write_config(dir.path(), "per-rank", 1);
    let single_config = write_config(dir.path(), "single", 2);

    let started = Instant::now();
    let ranks = dir.path().join("ranks");
    let log = succeeded(&train(2, &per_rank, &ranks, false, None));
    let two_ranks_s = started.elapsed().as_secs_f64();
    assert!(log.contains("every rank holds the same weights"), "no agreement of the ranks logged:\n{log}");
    assert!(log.contains(&format!("trained steps 0..{STEPS}")), "rank 0 reports the run:\n{log}");
    assert_eq!(log.matches("trained steps").count(), 1, "rank 0 alone reports:\n{log}");
    assert_eq!(checkpoint_folders(&ranks), ["step-00000002", "step-00000004"].map(String::from));
    assert_eq!(train_records(&ranks), STEPS as usize, "one metrics record per step, rank 0's");

    let single = dir.path().join("single");
    succeeded(&train(1, &single_config, &single, false, None));
    let difference = largest_difference(&weights(&ranks, STEPS), &weights(&single, STEPS));
    assert!(difference <= 1e-5, "two ranks and one process at twice the accumulation differ by {difference}");
    eprintln!("two ranks: {two_ranks_s:.1} s; largest weight difference to one process: {difference:e}");

    // Rank 1 exits as step 3 begins; the checkpoint of step 2 was complete before the ranks summed step 2.
    let killed = dir.path().join("killed");
    let failpoint = rank_exit_name(1, 3);
    let started = Instant::now();
    let output = train(2, &per_rank, &killed, false, Some(&failpoint));
    let ended_after = started.elapsed();
    let log = text(&output);
    assert!(!output.status.success(), "the job survived losing a rank:\n{log}");
    assert!(ended_after < Duration::from_secs(60), "the job took {ended_after:?} to end after losing a rank");
    assert!(log.contains(&format!("failpoint {failpoint} reached")), "no failure named:\n{log}");
    assert!(log.contains("exit"), "mpirun does not say that a rank exited:\n{log}");
    assert_eq!(checkpoint_folders(&killed), ["step-00000002"].map(String::from), "{log}");
    assert!(killed.join("checkpoints/step-00000002/state.json").exists(), "the checkpoint is complete");

    let log = succeeded(&train(2, &per_rank, &killed, true, None));
    assert!(log.contains(&format!("trained steps 2..{STEPS}")), "the resume starts at step 2:\n{log}");
    assert_eq!(weights(&killed, STEPS), weights(&ranks, STEPS), "the resumed run differs from the uninterrupted one");
    assert_eq!(train_records(&killed), STEPS as usize, "the metrics continue where the checkpoint was");
}
