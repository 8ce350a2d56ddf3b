//! The replay server: owns the prioritized replay buffer (`replay`) and serves it over zenoh.
//! Executors insert, the learner samples and sends new priorities, a monitor reads stats and state.
//! `run` is the whole role, so the binary and the in-process test harness share it.
//!
//! # Keys (under `rl/<run>/`)
//!
//! | key                     | direction | message                                            |
//! |-------------------------|-----------|----------------------------------------------------|
//! | `experience/*`          | in        | `ExperienceBatch` (subscriber)                     |
//! | `replay/sample`         | queryable | `SampleRequest` → `SampleReply` (batch or refusal)  |
//! | `replay/priorities`     | in        | `PriorityUpdate` (subscriber)                      |
//! | `replay/durable`        | out       | `DurableMarks` every `stats_interval_ms` once a snapshot is durable |
//! | `replay/state` (`?k=N`) | queryable | → `StatsReport` with `replay/top.<rank>.*` metrics  |
//! | `stats/replay/<id>`     | out       | `StatsReport` every `stats_interval_ms`             |
//! | `liveliness/replay/<id>`| token     | declared once every input is declared (readiness)  |
//!
//! `replay/state`'s reply reuses `StatsReport` so that any client decodes it with `proto::decode`.
//!
//! # Layout
//!
//! | file          | what                                                                         |
//! |---------------|------------------------------------------------------------------------------|
//! | `config.rs`   | [`ReplayServerConfig`] (`[replay_server]`), liveness and memory checks        |
//! | `limiter.rs`  | [`RateLimiter`]: minimum size, samples-per-insert with tolerance (sans-IO)    |
//! | `lockstep.rs` | deterministic mode: experience staged per block, priorities queued (sans-IO) |
//! | `service.rs`  | [`Service`]: buffer + limiter + counters + rejections, bytes in, replies out  |
//! | `rejects.rs`  | reasons for bad input, counts, rate-limited warnings                          |
//! | `pending.rs`  | blocked sample requests with deadlines (sans-IO)                              |
//! | `replica.rs`  | the snapshot replica: a second buffer fed the same operations, on a thread    |
//! | `snapshot.rs` | the snapshot file (server sidecar + buffer), atomic write, restore            |
//! | `streams.rs`  | [`Streams`]: decided batches per executor stream (re-send dedupe, durable marks) |
//! | `scan.rs`     | priority min/max/mean, ESS and top-k in chunks (short lock holds)             |
//! | `stats.rs`    | the `StatsReport`                                                             |
//! | `server.rs`   | the zenoh shell: declarations, insert/priority tasks, stats and snapshot timers |
//! | `sampler.rs`  | the query side: sample (hold, serve, refuse at deadline) and state            |
//!
//! # Guarantees
//!
//! - Every sample request is answered: a batch, or a typed refusal with a reason and a retry hint
//!   at the latest `request_deadline_ms` after it arrived; what waits and why is on the stats topic.
//! - Configurations that could never serve a sample are refused at start, with the reason.
//! - Bad input (undecodable, wrong kind or version, wrong dimensions, non-finite values, oversize)
//!   is counted by reason and logged at most once per reason every 5 s; serving continues.
//! - Memory: the buffer, the snapshot replica, its log and zenoh's queue of experience messages are
//!   bounded by `buffer.memory_budget_bytes` (checked at start, the log enforced at run time).
//! - Snapshots (periodic and at shutdown, atomic, versioned) restore contents, priorities,
//!   counters, the limiter and the sample sequence; requesting one holds the service for the
//!   enqueueing of one message.
#![deny(missing_docs)]

mod config;
mod limiter;
pub mod lockstep;
mod pending;
mod rejects;
mod replica;
mod sampler;
mod scan;
mod server;
mod service;
mod snapshot;
mod stats;
mod streams;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, anyhow};
pub use config::{InitialPriority, MAX_REQUEST_DEADLINE_MS, MAX_TOP_K, MemoryPlan, ReplayServerConfig};
pub use limiter::{Blocked, LimiterConfig, LimiterCounters, RateLimiter, Resumed};
use node::{Bus, Shutdown};
pub use pending::{Pending, Waiter};
pub use rejects::{Input, Rejection, Rejects};
use replay::ReplayBuffer;
pub use replica::SnapshotLog;
use run::RoleConfig;
pub use scan::{CHUNK as SCAN_CHUNK_TRANSITIONS, PriorityDigest, PriorityScan};
pub use service::{SampleOutcome, Service, ServiceCounters, Waiting};
pub use snapshot::{
    SERVER_SNAPSHOT_MAGIC, SERVER_SNAPSHOT_VERSION, Sidecar, SnapshotFileError, read_file,
    read_from as read_snapshot,
};
pub use streams::Streams;

use crate::replica::Replica;
use crate::server::Ctx;
use crate::snapshot::FileWriter;

/// `rl/<run>/replay/state`: the state and top-k queryable.
pub fn state_key(run: &proto::RunId) -> String {
    proto::Topic::ReplayState.key(run)
}

/// Snapshot figures of one run of the server.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct SnapshotReport {
    /// Snapshots written, periodic and final.
    pub written: u64,
    /// Snapshots that failed.
    pub failed: u64,
    /// Periodic snapshots abandoned because the replica's log outgrew its budget.
    pub aborted: u64,
    /// Sequence number of the snapshot written at shutdown.
    pub final_sequence: Option<u64>,
    /// Longest time a snapshot request held the service, µs.
    pub request_pause_max_us: u64,
    /// How long each periodic snapshot request held the service, µs, in order.
    pub request_pauses_us: Vec<u64>,
}

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
    /// The snapshot restored at start, by sequence number.
    pub restored_sequence: Option<u64>,
    /// Transitions stored at shutdown.
    pub size_transitions: u64,
    /// Inserts, samples, priority updates (applied and stale), refusals and time blocked, since the
    /// first start of this buffer (restored counters included).
    pub counters: ServiceCounters,
    /// Rejected messages by `<input>/<reason>`, since the first start.
    pub rejected: BTreeMap<String, u64>,
    /// Snapshots.
    pub snapshots: SnapshotReport,
    /// Decided batches per executor stream at shutdown.
    pub streams: Streams,
}

/// Runs the replay server until `shutdown` fires, then writes the final snapshot (if configured).
pub async fn run(config: ReplayServerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    config.validate().map_err(|m| anyhow!("config table [replay_server] is invalid: {m}"))?;
    let started = Instant::now();
    let restored = restore(&config).await?;
    let restored_sequence = restored.as_ref().map(|(_, sidecar)| sidecar.sequence);
    let restored_marks = restored.as_ref().map(|(_, sidecar)| sidecar.durable_marks());
    let (buffer, sidecar) = match restored {
        Some((buffer, sidecar)) => (buffer, Some(sidecar)),
        None => (ReplayBuffer::new(config.buffer.clone(), config.dims())?, None),
    };
    let replica = match &config.snapshot_path {
        Some(path) => {
            // A fresh buffer is built rather than cloned: its zeroed pages stay untouched until used.
            let copy = if sidecar.is_some() {
                buffer.clone()
            } else {
                ReplayBuffer::new(config.buffer.clone(), config.dims())?
            };
            let writer = FileWriter::new(path.clone());
            Some(Replica::start(copy, writer, config.snapshot_log_budget_bytes)?)
        }
        None => None,
    };
    let (mut service, resumed) = Service::new(&config, buffer, sidecar);
    if let Resumed::Reset { saved } = &resumed {
        tracing::warn!(?saved, now = ?config.limiter(), "limiter configuration changed since the snapshot; new epoch");
    }
    if let Some(replica) = &replica {
        service.attach_replica(replica.link());
    }
    let plan = config.memory_plan();
    tracing::info!(
        size = service.buffer().len(),
        capacity = config.buffer.capacity_transitions,
        min_size_to_sample = config.min_size_to_sample,
        samples_per_insert = ?config.samples_per_insert,
        memory_planned_bytes = plan.total,
        restored = ?restored_sequence,
        "replay-server starting"
    );
    let ctx = Arc::new(Ctx::new(service, bus.clone(), config.clone()));
    ctx.set_durable(restored_marks);
    let tasks = server::start(&ctx, &shutdown).await?;
    // Declared last: a client that sees the token finds every input in place.
    let alive = bus.announce().await?;
    shutdown.wait().await;
    let joined = server::join_all(tasks).await;
    drop(alive);

    let mut snapshots = SnapshotReport::default();
    if config.lockstep.is_some() {
        // No final snapshot replaces the newest cut: it must reach the disk before the replica stops.
        wait_for_cut_written(&ctx, restored_sequence.unwrap_or(0)).await;
    }
    if let Some(replica) = replica {
        drop(ctx.lock().detach_replica());
        let log = tokio::task::spawn_blocking(move || replica.stop()).await?;
        (snapshots.written, snapshots.failed, snapshots.aborted) = (log.written, log.failed, log.aborted);
    }
    // In deterministic mode the newest cut is the snapshot to resume from: a shutdown one would
    // describe a moment no other role saved.
    if let Some(path) = config.snapshot_path.clone().filter(|_| config.lockstep.is_none()) {
        let writing = Arc::clone(&ctx);
        match tokio::task::spawn_blocking(move || write_final(&writing, path)).await? {
            Ok(marks) => {
                snapshots.written += 1;
                snapshots.final_sequence = Some(marks.snapshot_sequence);
                // Executors still up drop what this last snapshot holds from their spools.
                ctx.set_durable(Some(marks));
                ctx.publish_durable().await;
            }
            Err(e) => {
                snapshots.failed += 1;
                tracing::error!(error = %e, "final snapshot failed");
            }
        }
    }
    snapshots.request_pause_max_us = ctx.snapshot_pause_max_us.load(Ordering::Relaxed);
    snapshots.request_pauses_us = ctx
        .snapshot_pauses_us
        .lock()
        .map(|p| p.clone())
        .unwrap_or_else(|poisoned| poisoned.into_inner().clone());
    let report = {
        let service = ctx.lock();
        Report {
            uptime_s: started.elapsed().as_secs_f64(),
            restored_sequence,
            size_transitions: service.buffer().len() as u64,
            counters: service.counters().clone(),
            rejected: service.rejects().counts().clone(),
            snapshots,
            streams: service.streams().clone(),
        }
    };
    drop(ctx);
    bus.close().await?;
    joined?;
    Ok(report)
}

/// Deterministic mode: waits (at most a minute) until the newest cut requested since `restored`
/// is on disk.
async fn wait_for_cut_written(ctx: &Ctx, restored: u64) {
    let deadline = Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let (wanted, log) = {
            let service = ctx.lock();
            (service.snapshot_sequence(), service.replica().map(|r| r.log()))
        };
        let Some(log) = log.filter(|_| wanted > restored) else { return };
        if log.last_sequence >= wanted {
            return;
        }
        if Instant::now() >= deadline {
            tracing::error!(
                sequence = wanted,
                "deterministic mode: the newest cut was not written within a minute"
            );
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}

/// Restores the configured snapshot, off the async runtime (it may be half a gigabyte).
async fn restore(config: &ReplayServerConfig) -> anyhow::Result<Option<(ReplayBuffer, Sidecar)>> {
    let Some(path) = config.snapshot_path.clone() else { return Ok(None) };
    let (cfg, dims) = (config.buffer.clone(), config.dims());
    let shown = path.display().to_string();
    let restored = tokio::task::spawn_blocking(move || read_file(&path, cfg, dims))
        .await?
        .with_context(|| format!("restoring the replay snapshot {shown} (move it away to start empty)"))?;
    if let Some((buffer, sidecar)) = &restored {
        tracing::info!(
            path = %shown,
            sequence = sidecar.sequence,
            size = buffer.len(),
            inserted = sidecar.counters.inserted_transitions,
            "restored snapshot"
        );
    }
    Ok(restored)
}

/// Writes the shutdown snapshot from the service's own buffer (every task has stopped); returns
/// what it made durable.
fn write_final(ctx: &Ctx, path: std::path::PathBuf) -> Result<proto::DurableMarks, SnapshotFileError> {
    let mut service = ctx.lock();
    let sidecar = service.next_sidecar(node::unix_ms());
    let mut writer = FileWriter::new(path);
    let times = writer.write(service.buffer(), &sidecar, &AtomicBool::new(false), |_| {})?;
    writer.finish()?;
    tracing::info!(sequence = sidecar.sequence, bytes = times.bytes, "final snapshot written");
    Ok(sidecar.durable_marks())
}
