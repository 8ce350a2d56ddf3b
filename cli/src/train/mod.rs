//! `sac-lsp train`: single-machine SAC-LSP (the dissertation's "SAC-LSP" and "Prioritized SAC-LSP"
//! runs) on any task, with per-epoch metrics (`metrics.csv` and TensorBoard events under
//! `tensorboard/`), periodic checkpoints and the best-evaluated weights
//! (`checkpoints/best-policy.safetensors`, [`learner::BestPolicy`]).

mod config;
mod record;
mod run_config;
mod trainer;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
pub use config::TrainConfig;
use record::MetricsFile;

use crate::progress::Progress;
use crate::tensorboard::EventWriter;
pub use run_config::RunConfig;
pub use trainer::Trainer;

/// Options of `sac-lsp train` (flags override the run file's `[train]` table).
#[derive(Debug, Args)]
#[command(
    after_help = "Examples:\n  sac-lsp train --config deploy/configs/inverted-pendulum.toml\n  sac-lsp train --config deploy/configs/ant-v5.toml --minutes 30 --out runs/ant-30min"
)]
pub struct TrainArgs {
    /// Run file with `[train]`, `[agent]` and `[replay]` tables (see deploy/configs/).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Task (overrides `[train] task`).
    #[arg(long)]
    task: Option<String>,
    /// Seed (overrides `[train] seed`).
    #[arg(long)]
    seed: Option<u64>,
    /// Epochs (overrides `[train] epochs`).
    #[arg(long)]
    epochs: Option<u64>,
    /// Stop after the first epoch that ends past this many minutes of wall-clock time.
    #[arg(long)]
    minutes: Option<f64>,
    /// Output folder for metrics.csv and checkpoints (default runs/train-<task>-<unix seconds>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// How batches are drawn (overrides `[replay] mode`): `uniform` is the dissertation's
    /// "SAC-LSP", `prioritized` its "Prioritized SAC-LSP".
    #[arg(long, value_enum)]
    replay_mode: Option<ReplayMode>,
}

/// `--replay-mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ReplayMode {
    /// Uniform sampling.
    Uniform,
    /// Proportional prioritized sampling.
    Prioritized,
}

/// Runs `sac-lsp train`.
pub fn run(args: &TrainArgs) -> Result<()> {
    let mut config = RunConfig::load(args.config.as_deref())?;
    if let Some(task) = &args.task {
        config.train.task = task.clone();
    }
    config.train.seed = args.seed.unwrap_or(config.train.seed);
    config.train.epochs = args.epochs.unwrap_or(config.train.epochs);
    if let Some(mode) = args.replay_mode {
        config.replay.mode = match mode {
            ReplayMode::Uniform => replay::SamplingMode::Uniform,
            ReplayMode::Prioritized => replay::SamplingMode::Prioritized,
        };
    }
    let config = config.fitted()?;
    let out = match &args.out {
        Some(dir) => dir.clone(),
        None => {
            let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?.as_secs();
            PathBuf::from(format!("runs/train-{}-{now}", config.train.task))
        }
    };
    std::fs::create_dir_all(out.join("checkpoints"))
        .with_context(|| format!("creating {}", out.display()))?;
    std::fs::write(out.join("config.txt"), format!("{config:#?}\n"))?;
    let mut metrics = MetricsFile::create(&out.join("metrics.csv"))?;
    let mut board = EventWriter::create(&out.join("tensorboard"), unix_s())?;
    tracing::info!(out = %out.display(), task = %config.train.task, epochs = config.train.epochs, "training");

    let started = Instant::now();
    let (epochs, checkpoint_every) = (config.train.epochs, config.train.checkpoint_every_epochs);
    let (eval_episodes, eval_mode) = (config.train.eval_episodes, config.train.eval_mode);
    let mut best = learner::BestPolicy::open(&out.join("checkpoints"));
    let mut trainer = Trainer::new(config)?;
    let mut progress = Progress::new("epochs", epochs);
    for epoch in 0..epochs {
        let record = trainer.run_epoch()?;
        progress.inc(&format!("eval return {:.1}", record.evaluation.mean_return));
        metrics.append(&record)?;
        board.write(unix_s(), record.env_steps, &record.scalars())?;
        board.flush()?;
        let evaluation = record.evaluation.report(epoch, record.updates, eval_episodes, eval_mode);
        if best.beats(&evaluation) {
            best.offer(&evaluation, &trainer.learner().snapshot()?).context("writing the best policy")?;
        }
        tracing::info!(
            epoch,
            env_steps = record.env_steps,
            replay_size = trainer.replay().len(),
            eval_return = format!("{:.1}", record.evaluation.mean_return),
            train_return = format!("{:.1}", record.train_return),
            updates_per_s = format!("{:.0}", record.updates_per_s),
            q_loss = format!("{:.3}", record.q_loss),
            "epoch"
        );
        let last =
            epoch + 1 == epochs || args.minutes.is_some_and(|m| started.elapsed().as_secs_f64() > m * 60.0);
        if last || (checkpoint_every > 0 && (epoch + 1).is_multiple_of(checkpoint_every)) {
            write_checkpoint(&out, epoch, &trainer)?;
        }
        if last {
            break;
        }
    }
    progress.finish();
    Ok(())
}

fn unix_s() -> f64 {
    node::unix_ms() as f64 / 1000.0
}

/// Writes `checkpoints/epoch-<n>.safetensors` atomically and durably (`node::durable`).
fn write_checkpoint(out: &Path, epoch: u64, trainer: &Trainer) -> Result<()> {
    let checkpoint = trainer.checkpoint()?;
    let path = out.join("checkpoints").join(format!("epoch-{epoch:05}.safetensors"));
    node::durable::write(&path, &checkpoint.safetensors)?;
    tracing::info!(path = %path.display(), learner_step = checkpoint.step, "checkpoint");
    Ok(())
}
