//! `sac-lsp monitor`: watches a run on the bus. It subscribes to every process's stats, the
//! executors' episodes and barrier reports, the learner's evaluations, the global step and the
//! liveliness tokens; redraws a live text view every interval (plain lines when stdout is not a
//! terminal); appends everything to a JSONL record (`record`) that `sac-lsp plot` turns into learning
//! curves; and writes the same figures as TensorBoard events (`board`).
//!
//! The monitor only listens: it declares no liveliness token and publishes nothing, so it can join
//! and leave a run at any time without the barrier noticing.

mod board;
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

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use clap::Args;
use proto::{RunId, topics};
use zenoh::sample::SampleKind;

use board::Board;
use journal::Journal;
use record::{Record, StartRecord};
use state::MonitorState;
use tick::Now;

/// `sac-lsp monitor` options.
#[derive(Debug, Args)]
#[command(
    after_help = "Example (a run started by deploy/local.sh on this machine):\n  sac-lsp monitor --run-id ID --connect tcp/127.0.0.1:7447"
)]
pub struct MonitorArgs {
    /// The bus options shared with the roles (--id and --config are ignored).
    #[command(flatten)]
    pub node: node::NodeArgs,
    /// JSONL record to append to [default: runs/<run-id>/monitor.jsonl].
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// TensorBoard event folder [default: `tensorboard/` beside the record].
    #[arg(long, value_name = "DIR")]
    pub tensorboard: Option<PathBuf>,
    /// Write no TensorBoard events.
    #[arg(long, conflicts_with = "tensorboard")]
    pub no_tensorboard: bool,
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
    let board_dir = args.tensorboard.clone().unwrap_or_else(|| out.with_file_name("tensorboard"));
    let mut sinks = Sinks {
        journal: Journal::open(&out)?,
        board: if args.no_tensorboard { None } else { Some(Board::create(&board_dir, node::unix_ms())?) },
    };
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
    let mut state = MonitorState::new(run.clone());
    sinks.write(&Record::Start(StartRecord { unix_ms: node::unix_ms(), run_id: run.to_string() }), &state)?;
    sinks.flush()?;
    tracing::info!(
        run = %run,
        record = %sinks.journal.path().display(),
        tensorboard = %sinks.board.as_ref().map_or("off".into(), |b| b.path().display().to_string()),
        "monitor up"
    );

    // A full-screen view only where someone watches it; a log or a pipe gets a plain line now and then.
    let view = if args.quiet {
        View::Off
    } else if std::io::stdout().is_terminal() {
        View::Screen
    } else {
        View::Lines { last_ms: None }
    };
    let mut view = view;
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
                    sinks.write(&Record::Episode(record), &state)?;
                }
            }
            Ok(sample) = evals.recv_async() => {
                if let Some(record) = state.on_eval(now(), &sample.payload().to_bytes()) {
                    sinks.write(&Record::Eval(record), &state)?;
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
                view.show(&state, &tick, sinks.journal.path())?;
                sinks.write(&Record::Tick(tick), &state)?;
                sinks.flush()?;
            }
        }
    }
    // A last tick, so the record ends with the state at exit.
    sinks.write(&Record::Tick(state.tick(now())), &state)?;
    sinks.flush()?;
    drop((stats, episodes, evals, steps, barriers, live));
    session.close().await.map_err(|e| anyhow!("closing the zenoh session: {e}"))?;
    println!("recorded to {}", sinks.journal.path().display());
    Ok(())
}

/// Where record lines go: the JSONL journal and, as scalars, TensorBoard.
struct Sinks {
    journal: Journal,
    board: Option<Board>,
}

impl Sinks {
    fn write(&mut self, record: &Record, state: &MonitorState) -> Result<()> {
        self.journal.append(&record.to_json())?;
        if let Some(board) = self.board.as_mut() {
            board.on_record(record, &state.reports_sorted())?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        self.journal.flush()?;
        self.board.as_mut().map_or(Ok(()), Board::flush)
    }
}

/// Milliseconds between two plain status lines when stdout is not a terminal.
const LINE_EVERY_MS: u64 = 10_000;

/// How the monitor shows the run on stdout.
enum View {
    /// `--quiet`.
    Off,
    /// Redraw the full screen every tick.
    Screen,
    /// One summary line every [`LINE_EVERY_MS`].
    Lines { last_ms: Option<u64> },
}

impl View {
    fn show(&mut self, state: &MonitorState, tick: &tick::Tick, record: &std::path::Path) -> Result<()> {
        let mut stdout = std::io::stdout().lock();
        match self {
            View::Off => return Ok(()),
            View::Screen => {
                write!(stdout, "{}{}", view::CLEAR, view::render(state, tick))?;
                writeln!(stdout, "\nrecording to {} (Ctrl-C stops)", record.display())?;
            }
            View::Lines { last_ms } => {
                if last_ms.is_some_and(|last| tick.now.unix_ms < last + LINE_EVERY_MS) {
                    return Ok(());
                }
                *last_ms = Some(tick.now.unix_ms);
                writeln!(stdout, "{}", view::line(state, tick))?;
            }
        }
        stdout.flush()?;
        Ok(())
    }
}
