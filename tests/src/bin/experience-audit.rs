//! `experience-audit --config RUN_FILE --snapshot REPLAY_SNAPSHOT --spool SPOOL_DIR --executors N`:
//! the account of a stopped durable run's experience ([`cluster::audit`]): every stream's made mark
//! and every batch in the executors' spool ledgers against the replay server's final snapshot.
//! Prints one line per figure and exits 1 if any difference is unexplained (produced ≠ stored +
//! refused + dropped + pending + lost at kill). `deploy/soak.sh` runs it after its soak.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use replay_server::ReplayServerConfig;

/// Audits a stopped durable run's experience.
#[derive(Debug, Parser)]
#[command(name = "experience-audit")]
struct Args {
    /// The run file the run used (for the replay buffer's shape).
    #[arg(long)]
    config: PathBuf,
    /// The replay server's snapshot, written at its clean shutdown.
    #[arg(long)]
    snapshot: PathBuf,
    /// The executors' spool folder (`runs/<run-id>/spool`).
    #[arg(long)]
    spool: PathBuf,
    /// Executors 0..N.
    #[arg(long)]
    executors: u32,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let text = std::fs::read_to_string(&args.config)
        .with_context(|| format!("reading {}", args.config.display()))?;
    let config: ReplayServerConfig = cluster::role_config(&text)?;
    let (buffer, sidecar) = replay_server::read_file(&args.snapshot, config.buffer.clone(), config.dims())?
        .with_context(|| format!("no replay snapshot at {}", args.snapshot.display()))?;
    let audit = cluster::audit::audit(&args.spool, 0..args.executors, &sidecar.streams)?;
    let inserted = sidecar.counters.inserted_transitions;
    println!("snapshot: sequence {}, {} transitions held", sidecar.sequence, buffer.len());
    println!(
        "produced: {} transitions made ({} in {} ledgered batches)",
        audit.produced,
        audit.produced - audit.lost_at_kill,
        audit.produced_batches
    );
    println!(
        "stored: {} (the replay server counts {inserted} inserted; {} evicted by FIFO since)",
        audit.stored,
        inserted.saturating_sub(buffer.len() as u64)
    );
    println!(
        "duplicates recognised: {} batches re-sent and not stored twice",
        sidecar.counters.duplicate_batches
    );
    let rejected: Vec<String> = (sidecar.rejected.iter())
        .filter(|(key, _)| key.starts_with("experience/"))
        .map(|(key, n)| format!("{n} {key}"))
        .collect();
    println!(
        "refused: {} (the replay server's experience rejections, in messages: {})",
        audit.refused,
        if rejected.is_empty() { "none".to_string() } else { rejected.join(", ") }
    );
    let dropped: Vec<String> = audit.dropped.iter().map(|(why, n)| format!("{n} {why}")).collect();
    println!("dropped: {}", if dropped.is_empty() { "none".to_string() } else { dropped.join(", ") });
    println!("pending in spools: {}", audit.pending);
    println!(
        "lost at kill (in memory, by the made marks): {} over {} streams, at most {} in one",
        audit.lost_at_kill, audit.killed_streams, audit.lost_at_kill_max
    );
    println!(
        "unexplained: {} (in no decided, dropped or held batch), {} (ledgered past a made mark)",
        audit.lost, audit.unmarked
    );
    if let Err(why) = audit.check() {
        println!("audit failed: {why}");
        std::process::exit(1);
    }
    println!("audit passed: produced = stored + refused + dropped + pending + lost at kill");
    Ok(())
}
