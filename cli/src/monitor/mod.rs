//! `sac-lsp monitor`: watches a run on the bus. It subscribes to every process's stats, the
//! executors' episodes and barrier reports, the learner's evaluations, the global step and the
//! liveliness tokens; redraws a live text view every interval; and appends everything to a JSONL
//! record (`record`) that `sac-lsp plot` turns into learning curves.
//!
//! The monitor only listens: it declares no liveliness token and publishes nothing, so it can join
//! and leave a run at any time without the barrier noticing.

mod family;
#[cfg(test)]
pub mod fixtures;
mod journal;
pub mod record;
pub mod state;
mod steps;
#[cfg(test)]
mod tests;
pub mod tick;
mod view;

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use clap::Args;
use proto::{RunId, topics};
use zenoh::sample::SampleKind;

use journal::Journal;
use record::StartRecord;
use state::MonitorState;
use tick::Now;

/// `sac-lsp monitor` options.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// The bus options shared with the roles (--id and --config are ignored).
    #[command(flatten)]
    pub node: node::NodeArgs,
    /// JSONL record to append to [default: runs/<run-id>/monitor.jsonl].
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Milliseconds between redraws and tick records.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub interval_ms: u64,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long, value_name = "SECONDS")]
    pub duration_s: Option<f64>,
    /// Record only: no live view.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs the monitor until Ctrl-C/SIGTERM or `--duration-s`.
pub fn run(args: &MonitorArgs) -> Result<()> {
    let duration = args
        .duration_s
        .map(|s| Duration::try_from_secs_f64(s).map_err(|e| anyhow!("--duration-s {s}: {e}")))
        .transpose()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    runtime.block_on(watch(args, duration))
}

async fn watch(args: &MonitorArgs, duration: Option<Duration>) -> Result<()> {
    let run =
        RunId::new(args.node.run_id.as_str()).with_context(|| format!("--run-id {}", args.node.run_id))?;
    let out =
        args.out.clone().unwrap_or_else(|| PathBuf::from("runs").join(run.as_str()).join("monitor.jsonl"));
    let mut journal = Journal::open(&out)?;
    let config = node::BusConfig::from(&args.node).to_zenoh()?;
    let session = zenoh::open(config).await.map_err(|e| anyhow!("opening the zenoh session: {e}"))?;
    let subscribe = |key: String| {
        let session = session.clone();
        async move { session.declare_subscriber(&key).await.map_err(|e| anyhow!("subscribing to {key}: {e}")) }
    };
    let stats = subscribe(topics::stats_all(&run)).await?;
    let episodes = subscribe(topics::episodes_all(&run)).await?;
    let evals = subscribe(topics::evaluation(&run)).await?;
    let steps = subscribe(topics::control_step(&run)).await?;
    let barriers = subscribe(topics::control_barrier_all(&run)).await?;
    let live_key = topics::liveliness_all(&run);
    let live = session
        .liveliness()
        .declare_subscriber(&live_key)
        .history(true)
        .await
        .map_err(|e| anyhow!("subscribing to {live_key}: {e}"))?;

    let started = Instant::now();
    // Whole milliseconds, so the record reads `12.345`, not `12.345000917`.
    let now = || Now { unix_ms: node::unix_ms(), elapsed_s: started.elapsed().as_millis() as f64 / 1000.0 };
    journal.append(&StartRecord { unix_ms: node::unix_ms(), run_id: run.to_string() }.to_json())?;
    journal.flush()?;
    tracing::info!(run = %run, record = %journal.path().display(), "monitor up");

    let mut state = MonitorState::new(run);
    let mut shutdown = node::Shutdown::on_signals();
    let mut interval = tokio::time::interval(Duration::from_millis(args.interval_ms));
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let stop_after = async move {
        match duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(stop_after);
    loop {
        tokio::select! {
            _ = shutdown.wait() => break,
            _ = &mut stop_after => break,
            Ok(sample) = stats.recv_async() => state.on_stats(&sample.payload().to_bytes()),
            Ok(sample) = episodes.recv_async() => {
                if let Some(record) = state.on_episode(now(), &sample.payload().to_bytes()) {
                    journal.append(&record.to_json())?;
                }
            }
            Ok(sample) = evals.recv_async() => {
                if let Some(record) = state.on_eval(now(), &sample.payload().to_bytes()) {
                    journal.append(&record.to_json())?;
                }
            }
            Ok(sample) = steps.recv_async() => state.on_step(&sample.payload().to_bytes()),
            Ok(sample) = barriers.recv_async() => {
                state.on_barrier(sample.key_expr().as_str(), &sample.payload().to_bytes());
            }
            Ok(sample) = live.recv_async() => {
                state.on_liveliness(sample.key_expr().as_str(), sample.kind() == SampleKind::Put);
            }
            _ = interval.tick() => {
                let tick = state.tick(now());
                journal.append(&tick.to_json())?;
                journal.flush()?;
                if !args.quiet {
                    let mut stdout = std::io::stdout().lock();
                    write!(stdout, "{}{}", view::CLEAR, view::render(&state, &tick))?;
                    writeln!(stdout, "\nrecording to {} (Ctrl-C stops)", journal.path().display())?;
                    stdout.flush()?;
                }
            }
        }
    }
    // A last tick, so the record ends with the state at exit.
    journal.append(&state.tick(now()).to_json())?;
    journal.flush()?;
    drop((stats, episodes, evals, steps, barriers, live));
    session.close().await.map_err(|e| anyhow!("closing the zenoh session: {e}"))?;
    println!("recorded to {}", journal.path().display());
    Ok(())
}
