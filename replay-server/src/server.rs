//! The zenoh shell around [`Service`]: declarations, one task per input, stats and snapshot timers,
//! and the shutdown sequence. Handlers decode outside the lock and hold the service's `std` mutex
//! only for the buffer operation itself (tens of µs), which is why a blocking mutex is right here:
//! it is never held across an `.await`.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use anyhow::Context;
use node::{Bus, Shutdown, Subscriber, unix_ms};
use proto::{DurableMarks, ExperienceBatch, PriorityUpdate, StatsReport, Topic, TopicSet};
use tokio::sync::Notify;
use tokio::task::JoinSet;
use zenoh::sample::Sample;

use crate::config::ReplayServerConfig;
use crate::sampler;
use crate::scan::{CHUNK, PriorityDigest, PriorityScan};
use crate::service::{Service, Waiting};
use crate::stats::{RateMeter, Rates, ReportInputs};

/// What every task of the server shares.
#[derive(Debug)]
pub(crate) struct Ctx {
    pub service: Mutex<Service>,
    /// Signalled after each insert, so blocked sample requests are re-checked.
    pub inserted: Notify,
    pub bus: Bus,
    pub cfg: ReplayServerConfig,
    /// `cfg`'s memory plan total, reported with every stats report.
    memory_planned_bytes: u64,
    /// Transitions inserted per second over the last stats interval (f64 bits), for retry hints.
    pub insert_rate: AtomicU64,
    /// Longest time a snapshot request held the service, µs.
    pub snapshot_pause_max_us: AtomicU64,
    /// Every snapshot request's hold, µs (one per snapshot interval, capped).
    pub snapshot_pauses_us: Mutex<Vec<u64>>,
    /// What the newest durable snapshot (restored or written) made durable, for executors' spools.
    pub durable: Mutex<Option<DurableMarks>>,
}

impl Ctx {
    pub fn new(service: Service, bus: Bus, cfg: ReplayServerConfig) -> Self {
        Self {
            service: Mutex::new(service),
            inserted: Notify::new(),
            bus,
            memory_planned_bytes: cfg.memory_plan().total,
            cfg,
            insert_rate: AtomicU64::new(0),
            snapshot_pause_max_us: AtomicU64::new(0),
            snapshot_pauses_us: Mutex::new(Vec::new()),
            durable: Mutex::new(None),
        }
    }

    /// Takes `marks` as the newest durable ones unless newer are held.
    pub fn set_durable(&self, marks: Option<DurableMarks>) {
        let mut held = self.durable.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(marks) = marks
            && held.as_ref().is_none_or(|h| h.snapshot_sequence < marks.snapshot_sequence)
        {
            *held = Some(marks);
        }
    }

    /// Publishes the newest durable marks, if any snapshot is durable yet.
    pub async fn publish_durable(&self) {
        let marks = self.durable.lock().unwrap_or_else(PoisonError::into_inner).clone();
        let Some(marks) = marks else { return };
        if let Err(e) = self.bus.put(Topic::ReplayDurable, &marks).await {
            tracing::warn!(error = %e, "could not publish the durable marks");
        }
    }

    /// The service. A panic in a handler poisons the mutex; the state is still consistent (every
    /// buffer operation is all-or-nothing), so later handlers carry on.
    /// The stats report of `service` (locked by the caller, with `digest` scanned under the same
    /// hold) at `rates`: what the stats topic and the state query both publish.
    pub fn report(&self, service: &Service, rates: Rates, digest: Option<&PriorityDigest>) -> StatsReport {
        let snapshots = service.replica().map(|r| r.log());
        let inputs = ReportInputs {
            node: self.bus.node(),
            unix_ms: unix_ms(),
            rates,
            digest,
            snapshots: snapshots.as_ref(),
            memory_planned_bytes: self.memory_planned_bytes,
        };
        crate::stats::build(service, &inputs)
    }

    pub fn lock(&self) -> MutexGuard<'_, Service> {
        self.service.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Unix milliseconds of an earlier `Instant`.
pub(crate) fn unix_ms_of(at: Instant) -> u64 {
    unix_ms().saturating_sub(at.elapsed().as_millis() as u64)
}

/// Declares every input, spawns a task per input and timer, and returns them; each ends on `shutdown`.
pub(crate) async fn start(
    ctx: &Arc<Ctx>,
    shutdown: &Shutdown,
) -> anyhow::Result<JoinSet<anyhow::Result<()>>> {
    let bus = &ctx.bus;
    let queue = ctx.cfg.subscriber_queue_messages as usize;
    let experience = bus.subscribe(TopicSet::Experience, queue).await.context("the experience subscriber")?;
    let priorities =
        bus.subscribe(Topic::ReplayPriorities, queue).await.context("the priority subscriber")?;
    let sample = bus.queryable(Topic::ReplaySample, queue).await.context("the sample queryable")?;
    let state = bus.queryable(Topic::ReplayState, 16).await.context("the state queryable")?;
    let cut = bus.queryable(Topic::ReplayCut, 16).await.context("the cut queryable")?;
    let mut tasks = JoinSet::new();
    tasks.spawn(experience_loop(Arc::clone(ctx), experience, shutdown.clone()));
    tasks.spawn(priority_loop(Arc::clone(ctx), priorities, shutdown.clone()));
    tasks.spawn(sampler::sample_loop(Arc::clone(ctx), sample, shutdown.clone()));
    tasks.spawn(sampler::state_loop(Arc::clone(ctx), state, shutdown.clone()));
    tasks.spawn(sampler::cut_loop(Arc::clone(ctx), cut, shutdown.clone()));
    tasks.spawn(stats_loop(Arc::clone(ctx), shutdown.clone()));
    // In deterministic mode snapshots are the schedule's cuts, never a timer's.
    if ctx.cfg.snapshots_enabled() && ctx.cfg.snapshot_interval_s > 0 && ctx.cfg.lockstep.is_none() {
        tasks.spawn(snapshot_loop(Arc::clone(ctx), shutdown.clone()));
    }
    Ok(tasks)
}

/// The next received sample, or `None` once shutdown fires or the subscriber closes.
async fn next_sample(sub: &Subscriber, shutdown: &mut Shutdown) -> Option<Sample> {
    tokio::select! {
        biased;
        _ = shutdown.wait() => None,
        received = sub.recv() => received.ok(),
    }
}

async fn experience_loop(ctx: Arc<Ctx>, sub: Subscriber, mut shutdown: Shutdown) -> anyhow::Result<()> {
    loop {
        let Some(sample) = next_sample(&sub, &mut shutdown).await else { break };
        let payload = sample.payload().to_bytes();
        let now = Instant::now();
        if ctx.lock().check_experience_size(payload.len(), now).is_err() {
            continue;
        }
        let decoded = proto::decode::<ExperienceBatch>(&payload);
        let accepted = ctx.lock().accept_experience(decoded, now);
        if accepted.is_ok() {
            ctx.inserted.notify_one();
            wait_for_replica(&ctx, &mut shutdown).await;
        }
        // zenoh's channel is always ready under load and is not part of tokio's co-operative
        // budget: without this, a flood of inserts keeps this task on its worker and starves the
        // sample queryable (measured: 1 batch/s while inserting 130K transitions/s).
        tokio::task::yield_now().await;
    }
    Ok(())
}

/// Holds inserts back while the snapshot replica is over its log budget (outside snapshot writes,
/// which abandon instead), so memory stays within the plan; visible as a blocked insert.
async fn wait_for_replica(ctx: &Ctx, shutdown: &mut Shutdown) {
    let over = |ctx: &Ctx| ctx.lock().replica().map(|r| (r.needs_backpressure(), r.lag_bytes()));
    let Some((true, lag)) = over(ctx) else { return };
    let since = Instant::now();
    let why = format!("snapshot replica behind by {lag} bytes, over snapshot_log_budget_bytes");
    ctx.lock().set_insert_wait(Some(Waiting { count: 1, since_unix_ms: unix_ms(), why }));
    while matches!(over(ctx), Some((true, _))) && !shutdown.is_triggered() {
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    let mut service = ctx.lock();
    service.set_insert_wait(None);
    service.add_blocked_ms("insert_replica_behind", since.elapsed().as_millis() as u64);
}

async fn priority_loop(ctx: Arc<Ctx>, sub: Subscriber, mut shutdown: Shutdown) -> anyhow::Result<()> {
    loop {
        let Some(sample) = next_sample(&sub, &mut shutdown).await else { break };
        let decoded = proto::decode::<PriorityUpdate>(&sample.payload().to_bytes());
        // Rejections are counted and logged inside; nothing else to do with them here.
        let wake = {
            let mut service = ctx.lock();
            service.accept_priorities(decoded, Instant::now()).is_ok() && service.lockstep().is_some()
        };
        if wake {
            // In deterministic mode a held sample may be waiting for exactly this update.
            ctx.inserted.notify_one();
        }
        tokio::task::yield_now().await;
    }
    Ok(())
}

/// Runs a chunked priority scan, releasing the lock between chunks, then calls `report` with the
/// digest under the same lock hold as the last chunk. When the scan fits one chunk (up to
/// [`CHUNK`] transitions) the digest and whatever `report` reads from the service describe one
/// moment; a priority update landing between the two made a report claim an update whose
/// priorities it did not show. A longer scan describes the buffer over its duration.
pub(crate) async fn scan<R>(
    ctx: &Ctx,
    k: usize,
    report: impl FnOnce(&Service, Option<PriorityDigest>) -> R,
) -> R {
    let mut scan: Option<PriorityScan> = None;
    loop {
        // A scope, not `drop`: the guard must visibly end before the await for the future to be Send.
        {
            let service = ctx.lock();
            let running = scan.get_or_insert_with(|| PriorityScan::new(service.buffer(), k));
            if running.step(service.buffer(), CHUNK) {
                let digest = scan.take().and_then(PriorityScan::finish);
                return report(&service, digest);
            }
        }
        tokio::task::yield_now().await;
    }
}

async fn stats_loop(ctx: Arc<Ctx>, mut shutdown: Shutdown) -> anyhow::Result<()> {
    let period = Duration::from_millis(ctx.cfg.stats_interval_ms);
    let mut ticks = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut meter = RateMeter::new(ctx.lock().counters(), Instant::now());
    loop {
        tokio::select! {
            biased;
            _ = shutdown.wait() => break,
            _ = ticks.tick() => {}
        }
        let report = scan(&ctx, 0, |service, digest| {
            ctx.set_durable(service.replica().and_then(|r| r.log().durable));
            let rates = meter.rates(service.counters(), Instant::now());
            ctx.insert_rate.store(rates.inserts_per_s.to_bits(), Ordering::Relaxed);
            let mut report = ctx.report(service, rates, digest.as_ref());
            let pause = ctx.snapshot_pause_max_us.load(Ordering::Relaxed);
            report.push_metric("replay/snapshot_pause_max_us", pause as f64);
            report
        })
        .await;
        if let Err(e) = ctx.bus.put_stats(&report).await {
            tracing::warn!(error = %e, "could not publish stats");
        }
        // Every interval, not only when a snapshot lands: a restarted executor learns the marks
        // of its earlier streams within one interval.
        ctx.publish_durable().await;
    }
    Ok(())
}

async fn snapshot_loop(ctx: Arc<Ctx>, mut shutdown: Shutdown) -> anyhow::Result<()> {
    let period = Duration::from_secs(ctx.cfg.snapshot_interval_s);
    let mut ticks = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            biased;
            _ = shutdown.wait() => break,
            _ = ticks.tick() => {}
        }
        request_snapshot(&ctx);
    }
    Ok(())
}

/// Snapshot request holds kept for the report (about four days at one a minute).
const MAX_PAUSES_KEPT: usize = 4096;

/// Asks the replica for a snapshot and records how long the service was held for it (from
/// acquiring the lock to releasing it; waiting for the lock is not a pause of the service).
pub(crate) fn request_snapshot(ctx: &Ctx) -> bool {
    let mut service = ctx.lock();
    let started = Instant::now();
    let requested = service.request_snapshot(unix_ms());
    let held_us = started.elapsed().as_micros() as u64;
    drop(service);
    ctx.snapshot_pause_max_us.fetch_max(held_us, Ordering::Relaxed);
    let mut pauses = ctx.snapshot_pauses_us.lock().unwrap_or_else(PoisonError::into_inner);
    if pauses.len() < MAX_PAUSES_KEPT {
        pauses.push(held_us);
    }
    requested
}

/// Waits for every task; returns the first error, logging any later ones.
pub(crate) async fn join_all(mut tasks: JoinSet<anyhow::Result<()>>) -> anyhow::Result<()> {
    let mut first = Ok(());
    while let Some(joined) = tasks.join_next().await {
        match joined.context("a replay-server task panicked").and_then(|r| r) {
            Ok(()) => {}
            Err(e) if first.is_ok() => first = Err(e),
            Err(e) => tracing::error!(error = %e, "replay-server task failed"),
        }
    }
    first
}
