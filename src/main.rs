//! `dggt`: feedforward 4D reconstruction of dynamic driving scenes — the command-line entry point. Each
//! subcommand lives in [`commands`]; [`backend`] turns `--device` into burn devices.

mod backend;
mod commands;

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

use crate::commands::{
    bench, convert, devices, eval, inspect, parity, reconstruct, refine, refine_pairs, refine_train, stress, synth,
    train,
};

#[derive(Debug, Parser)]
#[command(name = "dggt", version, about = "Feedforward 4D reconstruction of dynamic driving scenes")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Synth(synth::Args),
    Convert(convert::Args),
    Inspect(inspect::Args),
    Parity(parity::Args),
    Train(train::Args),
    Reconstruct(reconstruct::Args),
    RefinePairs(refine_pairs::Args),
    RefineTrain(refine_train::Args),
    Stress(stress::Args),
    Eval(eval::Args),
    Bench(bench::Args),
    Devices(devices::Args),
    Refine(refine::Args),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")))
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Synth(args) => synth::run(args),
        Command::Convert(args) => convert::run(args),
        Command::Inspect(args) => inspect::run(args),
        Command::Parity(args) => parity::run(args),
        Command::Train(args) => train::run(args),
        Command::Reconstruct(args) => reconstruct::run(args),
        Command::RefinePairs(args) => refine_pairs::run(args),
        Command::RefineTrain(args) => refine_train::run(args),
        Command::Stress(args) => stress::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Devices(args) => devices::run(args),
        Command::Refine(args) => refine::run(args),
    }
}
