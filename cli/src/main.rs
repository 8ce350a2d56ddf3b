//! `sac-lsp`: the command-line front of the project: `rollout` (checking the environments against
//! other implementations), `train` (single-machine training), `monitor` (a live view and JSONL record
//! of a distributed run's topics), `plot` (PNG learning curves from that record), `eval` (a
//! checkpoint's returns), `render` (a video of a checkpoint's policy) and `router` (a zenoh router for a
//! host of a multi-host run).

use anyhow::Result;
use clap::{Parser, Subcommand};

mod csv;
mod eval;
mod monitor;
mod picture;
mod plot;
mod policy;
mod progress;
mod render;
mod rollout;
mod router;
mod tensorboard;
mod train;

/// Distributed SAC-LSP tools.
#[derive(Debug, Parser)]
#[command(name = "sac-lsp", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Step a task with actions from a CSV file and write the trajectory as CSV.
    Rollout(rollout::RolloutArgs),
    /// Train SAC-LSP on one machine (environment, replay and learner in this process).
    Train(train::TrainArgs),
    /// Watch a distributed run on the bus: a live view, and a JSONL record for `plot`.
    Monitor(monitor::MonitorArgs),
    /// Draw learning curves (PNG) from a `monitor` record.
    Plot(plot::PlotArgs),
    /// Evaluate a checkpoint's policy: N episodes, per-episode CSV, JSON summary.
    Eval(eval::EvalArgs),
    /// Draw a checkpoint's policy acting: a GIF (or MP4) video and a PNG still, headless.
    Render(render::RenderArgs),
    /// A zenoh router for a host of a multi-host run: its executors connect to it as clients.
    Router(router::RouterArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Rollout(args) => rollout::run(&args),
        Command::Train(args) => train::run(&args),
        Command::Monitor(args) => monitor::run(&args),
        Command::Plot(args) => plot::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Render(args) => render::run(&args),
        Command::Router(args) => router::run(&args),
    }
}
