//! An executor: steps its own environment with the current stochastic policy, computes each
//! transition's initial priority with its local critics (Ape-X), and publishes batches of
//! transitions to the replay server, never more than the global-step barrier allows.
//! `run` is the whole role, so the binary and the in-process test harness share it.
//!
//! # Keys (under `rl/<run>/`)
//!
//! | key                         | direction | message                                              |
//! |-----------------------------|-----------|------------------------------------------------------|
//! | `control/step`              | in        | `GlobalStep`: the barrier and the newest weights version |
//! | `params/stream`             | in        | `WeightsSnapshot`: every new version, pushed once     |
//! | `params/weights` (get)      | query     | `WeightsSnapshot`, when joining or a push did not come |
//! | `params/frozen` (get)       | query     | `FrozenLevels`, once at start in a hierarchy         |
//! | `experience/<id>`           | out       | `ExperienceBatch` with initial priorities |δ|          |
//! | `episodes/<id>`             | out       | `EpisodeReport` per finished episode                 |
//! | `control/barrier/<id>`      | out       | `BarrierReport` every `report_interval_ms` and on each block/unblock |
//! | `stats/executor/<id>`       | out       | `StatsReport`: env steps/s, weights lag, what it waits on |
//! | `liveliness/executor/<id>`  | token     | declared once subscribed: the param server counts it live |
//! | `replay/durable`            | in        | `DurableMarks`: spooled batches the replay server made durable |
//! | `liveliness/replay/*`       | watch     | a replay server appearing: the spool is sent again    |
//!
//! # Layout
//!
//! | file         | what                                                                      |
//! |--------------|---------------------------------------------------------------------------|
//! | `config.rs`  | [`ExecutorConfig`]: `[executor]`, `[agent]`, `[train]` task and seed      |
//! | `rollout.rs` | [`Rollout`]: env + actor + pending batch, sans-IO                         |
//! | `inbox.rs`   | [`Inbox`]: newest step and weights, shell → thread                        |
//! | `worker.rs`  | the rollout thread: barrier, waits with reasons, loading weights          |
//! | `weights.rs` | the weights task: pushed versions, a `get` for what no push brought       |
//! | `push.rs`    | `PushTracker`: which pushed frame to take, when to ask, sans-IO           |
//! | `frozen.rs`  | a hierarchy's frozen levels, fetched once and checked against their hash  |
//! | `spool.rs`   | [`Spool`]: published batches on disk until durable (`[executor] spool_dir`) |
//! | `stats.rs`   | the stats report                                                          |
//!
//! The environment and the networks run on their own thread; the async shell only moves messages,
//! so fetching weights never stalls stepping (they are loaded between two steps).
#![deny(missing_docs)]

mod config;
mod frozen;
mod inbox;
mod push;
mod rollout;
mod spool;
mod stats;
mod weights;
mod worker;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::{Actor, PolicyStack};
pub use config::{ExecutorConfig, ExecutorSettings};
pub use inbox::{Control, Inbox, Taken};
use node::{Bus, Delivery, Publisher, Rejects, Shutdown};
use proto::{DurableMarks, GlobalStep, Topic};
pub use rollout::{Rollout, StepOutcome};
pub use spool::{Ledger, LedgerEntry, MadeMark, Released, Spool, SpoolCounts, read_ledger};
use tokio::sync::{mpsc, watch};
pub use weights::{PUSH_GRACE, WeightsTaken};
pub use worker::{Out, Progress, Wait, WorkerReport};
use zenoh::sample::SampleKind;

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
    /// The rollout thread's report.
    pub worker: WorkerReport,
    /// Weight versions taken, by how they came.
    pub weights: WeightsTaken,
    /// Experience batches published.
    pub batches_published: u64,
    /// Rejected inputs by reason.
    pub rejected: std::collections::BTreeMap<String, u64>,
    /// The spool's figures at shutdown, when it spools.
    pub spool: Option<SpoolCounts>,
}

/// Messages the rollout thread may have queued for the async shell (batches among them). With the
/// batch each side holds and the rollout's pending transitions, this bounds what a killed executor
/// loses in memory: at most `(OUT_QUEUE + 2) × batch_transitions` plus what one step adds (an
/// episode's relabelled copies with `[her]`), counted by the spool's made marks.
pub const OUT_QUEUE: usize = 64;

/// Seeds of executor `id` in a run seeded `seed`: distinct streams per executor (splitmix64).
pub fn executor_seed(seed: u64, id: u32) -> u64 {
    run::mix_seed(seed, id)
}

/// Runs the executor until `shutdown` fires.
pub async fn run(config: ExecutorConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let id = bus.node().id;
    if let Some(schedule) = config.run.lockstep
        && id >= schedule.executors
    {
        anyhow::bail!(
            "deterministic mode runs executors 0..{} ([lockstep] executors); this is executor {id}",
            schedule.executors
        );
    }
    let seed = executor_seed(config.run.seed(), id);
    let (her, task) = (&config.run.her, config.run.task);
    let env = sim::her::make(her, task, seed)?;
    let hindsight = sim::her::hindsight(her, task, seed.wrapping_add(2));
    let rejects = Arc::new(Mutex::new(Rejects::default()));
    let ms = Duration::from_millis;
    let (stack, stack_hash) = match config.run.hierarchy.depth() {
        0 => (PolicyStack::empty(), None),
        depth => {
            let (timeout, deadline) =
                (ms(config.executor.weights_timeout_ms), ms(config.executor.wait_deadline_ms));
            match frozen::fetch(&bus, depth, timeout, deadline, &rejects, shutdown.clone()).await {
                Some(fetched) => (fetched.stack, Some(fetched.hash)),
                None => {
                    bus.close().await?;
                    return Ok(Report::default());
                }
            }
        }
    };
    let actor = Actor::with_stack(config.agent.clone(), stack, seed.wrapping_add(1))?;
    let mut spool = match &config.executor.spool_dir {
        Some(dir) => Some(
            Spool::open(dir, id, config.executor.spool_max_bytes)
                .map_err(|e| anyhow::anyhow!("opening the spool in {}: {e}", dir.display()))?,
        ),
        None => None,
    };
    let stream = if spool.is_some() { new_stream() } else { 0 };
    // Durable experience: what the rollout makes is marked on disk before it can reach a batch, so
    // what a kill leaves in memory is counted (`spool.rs`).
    let made = match &spool {
        Some(spool) => Some(
            spool.made_mark(stream).map_err(|e| anyhow::anyhow!("creating the spool's made mark: {e}"))?,
        ),
        None => None,
    };
    let mut rollout = Rollout::new(id, env, actor, seed)
        .with_episode_limit(config.executor.max_episode_steps)
        .with_hindsight(hindsight)
        .with_stream(stream);
    if let Some(schedule) = config.run.lockstep {
        // Deterministic mode: start where the replay server's newest cut says the run is.
        let Some(cut) = node::ask_cut(&bus, shutdown.clone()).await? else {
            bus.close().await?;
            return Ok(Report::default());
        };
        let start = if cut.learner_step == 0 { 0 } else { schedule.needed_for(cut.learner_step) };
        let delivered = cut.progress.get(id as usize).copied().unwrap_or(0);
        if delivered != start {
            anyhow::bail!(
                "deterministic mode: the replay server holds {delivered} env steps of executor {id}, past \
                 its checkpoint at learner step {} ({start} steps): an executor cannot rejoin mid-run; \
                 resume the whole run from its last checkpoint",
                cut.learner_step
            );
        }
        if start > 0 {
            tracing::info!(
                learner_step = cut.learner_step,
                env_steps = start,
                "deterministic mode: resuming at the cut"
            );
            rollout = rollout.with_env_steps(start);
            rollout.restart_streams(run::Lockstep::cut_seed(config.run.seed(), id, cut.learner_step));
        }
    }

    let queue = node::DEFAULT_QUEUE;
    let step_sub = bus.subscribe(Topic::ControlStep, queue).await?;
    let experience_pub = bus.publisher(Topic::Experience { executor_id: id }, Delivery::Block).await?;
    let durable_sub = bus.subscribe(Topic::ReplayDurable, queue).await?;
    // Current tokens are delivered at declaration: a replay server already up counts as appearing,
    // so what earlier runs of this executor left in the spool is sent at once.
    let replay_sub = bus.watch(proto::Role::Replay).await?;
    // Deterministic mode asks for exact versions; otherwise new ones come by push.
    let pushed = if config.executor.weights_push && config.run.lockstep.is_none() {
        Some(bus.subscribe(Topic::ParamsStream, weights::PUSH_QUEUE).await?)
    } else {
        None
    };
    let _alive = bus.announce().await?;
    tracing::info!(seed, task = %config.run.task, spool = spool.is_some(), "executor up");

    let inbox = Arc::new(Inbox::default());
    let (out_tx, mut out_rx) = mpsc::channel(OUT_QUEUE);
    let (wanted_tx, wanted_rx) = watch::channel(None);
    let lockstep = config.run.lockstep.map(|schedule| worker::Lockstep {
        schedule,
        seed: config.run.seed(),
        wanted: wanted_tx,
        staged: None,
    });
    let exact = lockstep.is_some().then_some(wanted_rx);
    let worker = {
        let (inbox, settings) = (inbox.clone(), config.executor.clone());
        std::thread::Builder::new()
            .name(format!("rollout-{id}"))
            .spawn(move || worker::run(id, rollout, inbox, out_tx, settings, lockstep, made))?
    };

    let mut report = Report::default();
    // Weights are fetched on a task of their own, so a slow or absent param server never holds up
    // publishing (and with it the rollout thread).
    let (announced_tx, announced_rx) = watch::channel(None);
    let fetcher = tokio::spawn(weights::fetch_loop(weights::Fetch {
        bus: bus.clone(),
        announced: announced_rx,
        exact,
        pushed,
        inbox: inbox.clone(),
        timeout: Duration::from_millis(config.executor.weights_timeout_ms),
        stack: stack_hash,
        rejects: rejects.clone(),
        shutdown: shutdown.clone(),
    }));
    let mut worker_done = false;
    loop {
        tokio::select! {
            _ = shutdown.wait() => break,
            Ok(sample) = step_sub.recv() => match proto::decode::<GlobalStep>(&sample.payload().to_bytes()) {
                Ok(step) => {
                    inbox.set_step(step);
                    announced_tx.send_if_modified(|v| {
                        let changed = *v != Some(step.weights_version);
                        *v = Some(step.weights_version);
                        changed
                    });
                }
                Err(error) => lock(&rejects).decode_failed("step", &error),
            },
            message = out_rx.recv() => match message {
                Some(message) => {
                    let spool = spool.as_mut();
                    publish(&bus, &experience_pub, id, message, &mut report, &rejects, spool).await;
                }
                None => { worker_done = true; break; }
            },
            Ok(sample) = durable_sub.recv() => match proto::decode::<DurableMarks>(&sample.payload().to_bytes()) {
                Ok(marks) => if let Some(spool) = spool.as_mut() {
                    match spool.on_marks(&marks) {
                        Ok(released) => resend(spool, &experience_pub, released.stalled, "a stream's durable prefix stalled").await,
                        Err(error) => tracing::warn!(%error, "could not release durable batches from the spool"),
                    }
                },
                Err(error) => lock(&rejects).decode_failed("durable", &error),
            },
            Ok(sample) = replay_sub.recv() => {
                if sample.kind() == SampleKind::Put && let Some(spool) = spool.as_mut() {
                    let held = spool.held();
                    resend(spool, &experience_pub, held, "a replay server appeared").await;
                }
            }
        }
    }
    inbox.stop();
    // Drain what the thread still sends (its final flush) until it hangs up.
    while !worker_done {
        match tokio::time::timeout(Duration::from_secs(10), out_rx.recv()).await {
            Ok(Some(message)) => {
                publish(&bus, &experience_pub, id, message, &mut report, &rejects, spool.as_mut()).await;
            }
            Ok(None) => worker_done = true,
            Err(_) => anyhow::bail!("the rollout thread did not stop within 10 s"),
        }
    }
    report.worker = match worker.join() {
        Ok(result) => result?,
        Err(_) => anyhow::bail!("the rollout thread panicked"),
    };
    drop(announced_tx); // ends the fetch task if shutdown has not
    report.weights = fetcher.await?;
    report.uptime_s = started.elapsed().as_secs_f64();
    report.rejected = lock(&rejects).counts().clone();
    report.spool = spool.as_ref().map(Spool::counts);
    drop((step_sub, experience_pub, durable_sub, replay_sub));
    bus.close().await?;
    Ok(report)
}

/// The shared rejection counts (a panicking holder leaves plain counters behind: keep them).
fn lock(rejects: &Mutex<Rejects>) -> std::sync::MutexGuard<'_, Rejects> {
    rejects.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A fresh stream id for this process's batches: nonzero, and (from the clock and the process id)
/// not one an earlier run of this executor used.
fn new_stream() -> u64 {
    let nanos =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64);
    executor_seed(nanos, std::process::id()).max(1)
}

/// Sends the spooled batches `keys` again, in order (the replay server stores each once).
async fn resend(spool: &mut Spool, experience: &Publisher, keys: Vec<spool::Key>, why: &str) {
    if keys.is_empty() {
        return;
    }
    tracing::info!(batches = keys.len(), why, "sending spooled batches again");
    for key in keys {
        let Some(frame) = spool.resend(key) else { continue };
        if let Err(error) = experience.put(frame).await {
            tracing::warn!(%error, "re-send failed");
            return;
        }
    }
}

async fn publish(
    bus: &Bus,
    experience: &Publisher,
    id: u32,
    message: Out,
    report: &mut Report,
    rejects: &Mutex<Rejects>,
    spool: Option<&mut Spool>,
) {
    let result = match message {
        Out::Experience(batch) => {
            let frame = match spool {
                // The spool keeps it until it is durable; a batch failing the wire checks, or whose
                // file cannot be written, is counted and named in the ledger there.
                Some(spool) => spool.push(&batch),
                None => Some(proto::encode(&batch)),
            };
            match frame {
                Some(frame) => {
                    report.batches_published += 1;
                    experience.put(frame).await
                }
                None => Ok(()),
            }
        }
        Out::Episode(episode) => bus.put(Topic::Episodes { executor_id: id }, &episode).await,
        Out::Barrier(barrier) => bus.put(Topic::ControlBarrier { executor_id: id }, &barrier).await,
        Out::Progress(progress) => {
            let counts = spool.map(|s| s.counts());
            let stats = stats::report(bus.node(), &progress, &lock(rejects), counts);
            bus.put_stats(&stats).await
        }
    };
    if let Err(error) = result {
        tracing::warn!(%error, "publish failed");
    }
}
