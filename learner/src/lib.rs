//! The learner: pulls prioritized batches from the replay server through a prefetch pipeline, runs
//! SAC-LSP updates, sends back priorities, publishes weights to the param server every M updates
//! and its step every few, evaluates once per epoch on a thread of its own, checkpoints every K
//! epochs, keeps the best-evaluated weights beside the checkpoints and resumes from the newest
//! checkpoint. `run` is the whole role, so the binary and the
//! in-process test harness share it.
//!
//! # Keys (under `rl/<run>/`)
//!
//! | key                   | direction | message                                        |
//! |-----------------------|-----------|------------------------------------------------|
//! | `replay/sample`       | query     | `SampleRequest` → `SampleReply`                 |
//! | `replay/priorities`   | out       | `PriorityUpdate` after every update            |
//! | `params/publish`      | out       | `WeightsSnapshot` every `publish_weights_every_updates` |
//! | `control/learner`     | out       | `LearnerStep` every `announce_every_updates`; every 250 ms while starved of data |
//! | `eval`                | out       | `EvalReport` per epoch                          |
//! | `stats/learner/<id>`  | out       | `StatsReport`: updates/s, losses, waiting        |
//! | `liveliness/learner/<id>` | token | declared at start                               |
//!
//! # Layout
//!
//! | file            | what                                                           |
//! |-----------------|----------------------------------------------------------------|
//! | `config.rs`     | [`LearnerConfig`]: `[learner]`, `[agent]`, `[train]` task and seed |
//! | `fetch.rs`      | the prefetch pipeline: request loops with timeouts and reasons  |
//! | `batch.rs`      | [`Sampled`]: wire batch → agent batch                           |
//! | `updater.rs`    | [`Updater`]: the update thread                                  |
//! | `evaluate.rs`   | [`evaluate`]: deterministic evaluation episodes                 |
//! | `checkpoint.rs` | [`CheckpointDir`]: atomic checkpoint files, resume              |
//! | `best.rs`       | [`BestPolicy`]: the best-evaluated weights so far               |
//! | `outbox.rs`     | publishing; the newest weights are re-sent to a late param server |
//! | `stats.rs`      | the stats report                                                |
#![deny(missing_docs)]

mod batch;
mod best;
mod checkpoint;
mod config;
mod evaluate;
mod fetch;
mod outbox;
mod stats;
mod updater;

use std::sync::Arc;
use std::sync::atomic::AtomicU64;
use std::time::{Duration, Instant};

use agent::{Actor, AnyLearner, ParamSnapshot, PolicyStack};
pub use batch::Sampled;
pub use best::BestPolicy;
pub use checkpoint::CheckpointDir;
pub use config::{LearnerConfig, LearnerSettings};
pub use evaluate::{Episode, Evaluation, evaluate, prepare_latent, run_episode, run_episode_watched};
pub use fetch::{FetchStatus, Fetcher, Requests, Waiting};
use node::{Bus, CutWait, Shutdown};
use proto::{EvalMode, EvalReport};
use tokio::sync::mpsc;
pub use updater::{Frozen, LossMeans, Out, Progress, Updater, UpdaterReport};

/// Waiting this long for data (the replay server refusing for lack of it) makes the learner tell the
/// param server it is starved.
const STARVED_AFTER: Duration = Duration::from_secs(1);

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
    /// The update thread's report (start and final step, weights published, checkpoints).
    pub updater: UpdaterReport,
    /// Evaluations completed.
    pub evaluations: Vec<EvalReport>,
    /// Times the newest weights were sent again because a param server started listening.
    pub weights_resent: u64,
    /// The prefetch pipeline's counters.
    pub fetch: FetchStatus,
}

/// Runs the learner until `shutdown` fires (or `max_updates` is reached).
pub async fn run(config: LearnerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = Instant::now();
    let s = config.learner.clone();
    let seed = config.run.seed();
    let checkpoints = s.checkpoint_dir.as_ref().map(CheckpointDir::new);
    let levels = config.run.hierarchy.read().map_err(anyhow::Error::msg)?;
    let frozen = Frozen::new(PolicyStack::from_weights(&levels)?)?;
    frozen.stack.check_fits(&config.agent).map_err(|e| anyhow::anyhow!("[hierarchy]: {e}"))?;
    if let Some(hash) = frozen.hash {
        tracing::info!(levels = levels.len(), content_hash = %hash, "training on top of frozen levels");
    }
    let resume_from = match config.run.lockstep {
        Some(_) => match deterministic_resume(&bus, checkpoints.as_ref(), shutdown.clone()).await? {
            Some(checkpoint) => checkpoint,
            None => {
                bus.close().await?;
                return Ok(Report::default());
            }
        },
        None => checkpoints.as_ref().map(CheckpointDir::latest).transpose()?.flatten(),
    };
    let learner = match resume_from {
        Some(checkpoint) => {
            tracing::info!(step = checkpoint.step, "resuming from checkpoint");
            check_resumed_stack(&checkpoint, &frozen)?;
            AnyLearner::from_checkpoint(config.agent.clone(), &checkpoint, s.backend)?
        }
        None => AnyLearner::new(config.agent.clone(), seed, s.backend)?,
    };
    if s.backend == agent::Backend::Auto
        && let Err(why) = agent::FusedLearner::check_support(&config.agent)
    {
        // `auto` never falls back in silence: say which option keeps the fused learner out.
        tracing::warn!(%why, "backend auto: the candle learner runs the updates (about a third as fast)");
    }
    tracing::info!(backend = ?learner.backend(), step = learner.step(), "learner up");
    let step = Arc::new(AtomicU64::new(learner.step()));
    let _alive = bus.announce().await?;

    let (out_tx, mut out_rx) = mpsc::channel(256);
    let eval = if s.eval_episodes > 0 {
        let (tx, rx) = std::sync::mpsc::sync_channel::<(u64, ParamSnapshot)>(1);
        let env = sim::her::make(&config.run.her, config.run.task, seed.wrapping_add(3))?;
        let actor = Actor::with_stack(
            config.agent.clone(),
            PolicyStack::from_weights(&levels)?,
            seed.wrapping_add(5),
        )?;
        let (out, episodes, mode) = (out_tx.clone(), s.eval_episodes, s.eval_mode);
        let best = s.checkpoint_dir.as_deref().map(BestPolicy::open);
        std::thread::Builder::new()
            .name("evaluate".into())
            .spawn(move || evaluation_thread(env, actor, (episodes, mode), best, rx, out))?;
        Some(tx)
    } else {
        None
    };
    // Deterministic mode: one request in flight, for an exact step; its batches fit the channel, so
    // the next request goes out while they are used (the replay server holds it until the
    // priorities it must see have arrived).
    let (request_loops, channel) = match config.run.lockstep {
        Some(_) => (1, s.batches_per_request as usize),
        None => (s.prefetch_batches, s.prefetch_batches as usize),
    };
    let (batch_tx, batch_rx) = mpsc::channel(channel);
    let updater = Updater {
        learner,
        settings: s.clone(),
        out: out_tx,
        eval,
        checkpoints,
        step: step.clone(),
        frozen,
        lockstep: config.run.lockstep,
    };
    let update_thread =
        std::thread::Builder::new().name("update".into()).spawn(move || updater.run(batch_rx))?;

    let fetcher = Arc::new(Fetcher::default());
    let requests = Requests {
        bus: bus.clone(),
        fetcher: fetcher.clone(),
        step: step.clone(),
        batch_size: config.agent.batch_size as u32,
        batches_per_request: s.batches_per_request,
        timeout: Duration::from_millis(s.sample_timeout_ms),
        prioritized: s.send_priorities,
        exact_step: config
            .run
            .lockstep
            .map(|_| Arc::new(AtomicU64::new(step.load(std::sync::atomic::Ordering::Relaxed)))),
    };
    let loops: Vec<_> = (0..request_loops)
        .map(|_| tokio::spawn(fetch::request_loop(requests.clone(), batch_tx.clone(), shutdown.clone())))
        .collect();
    drop(batch_tx);

    let (mut outbox, matching) = outbox::Outbox::new(bus.clone()).await?;
    let announcements = bus.subscribe(proto::Topic::ControlStep, node::DEFAULT_QUEUE).await?;
    // Often enough for the param server's notice expiry, and to say "no longer" soon after a batch.
    let mut starved_check = tokio::time::interval(STARVED_AFTER / 4);
    let mut said_starved = false;
    loop {
        tokio::select! {
            _ = shutdown.wait() => break,
            _ = starved_check.tick() => {
                // The update thread says nothing while it has no batches; say it for it, so the param
                // server can tell a learner starved of data from a slow one: repeated while it lasts,
                // and once more when it ends (the next step message may be a while away).
                let starved = fetcher.status().starved(node::unix_ms(), STARVED_AFTER);
                if starved || said_starved {
                    said_starved = starved;
                    let message = proto::LearnerStep {
                        learner_step: step.load(std::sync::atomic::Ordering::Relaxed),
                        weights_version: outbox.weights_version,
                        starved,
                    };
                    outbox.send(Out::Step(message), &fetcher).await;
                }
            }
            Ok(status) = matching.recv_async() => if status.matching() {
                outbox.resend_weights().await;
            },
            Ok(sample) = announcements.recv() => match proto::decode::<proto::GlobalStep>(&sample.payload().to_bytes()) {
                Ok(announced) => {
                    let starved = fetcher.status().starved(node::unix_ms(), STARVED_AFTER);
                    outbox.on_announcement(announced.weights_version, starved).await;
                }
                Err(error) => fetcher.bad_announcement(&error),
            },
            message = out_rx.recv() => match message {
                Some(message) => outbox.send(message, &fetcher).await,
                None => break,
            },
        }
    }
    // Nothing reads the announcements from here on: undrained, their queue fills, zenoh's callback
    // then blocks a runtime thread and closing the session times out (seen after a long wait for
    // deterministic mode's last cut).
    drop(announcements);
    // Stop the request loops; the update thread then sees its batches end, publishes its final
    // weights and checkpoint, and hangs up.
    for request_loop in &loops {
        request_loop.abort();
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    while !update_thread.is_finished() {
        match tokio::time::timeout_at(deadline.into(), out_rx.recv()).await {
            Ok(Some(message)) => outbox.send(message, &fetcher).await,
            Ok(None) => tokio::time::sleep(Duration::from_millis(5)).await,
            Err(_) => anyhow::bail!("the update thread did not stop within 30 s"),
        }
    }
    let updater = match update_thread.join() {
        Ok(result) => result?,
        Err(_) => anyhow::bail!("the update thread panicked"),
    };
    while let Ok(message) = out_rx.try_recv() {
        outbox.send(message, &fetcher).await;
    }
    let last = updater.final_step;
    if let Some(schedule) = config.run.lockstep.filter(|l| l.is_cut(last) && last > updater.start_step) {
        // The replay server cuts its state here once the executors' blocks are in: wait for it, so
        // that a launcher stopping everything when this process ends leaves a resumable run.
        let every = schedule.checkpoint_every_updates;
        match node::wait_for_cut(&bus, last, Duration::from_secs(60), shutdown.clone()).await? {
            CutWait::Cut => {
                tracing::info!(step = last, "deterministic mode: every role's state is saved at this step")
            }
            CutWait::NoCuts => tracing::info!(
                step = last,
                "deterministic mode: the replay server has no snapshot_path, so this run cannot be resumed"
            ),
            CutWait::TimedOut => tracing::warn!(
                step = last,
                every,
                "deterministic mode: the replay server did not cut its state here within 60 s"
            ),
            CutWait::Stopped => {}
        }
    }
    let report = Report {
        uptime_s: started.elapsed().as_secs_f64(),
        updater,
        weights_resent: outbox.weights_resent,
        evaluations: std::mem::take(&mut outbox.evaluations),
        fetch: fetcher.status(),
    };
    // The listener first: undeclared after its publisher, zenoh logs an error for it.
    drop(matching);
    drop(outbox);
    bus.close().await?;
    Ok(report)
}

/// Deterministic mode's checkpoint to resume: the one of the replay server's newest cut (none for a
/// fresh run); `Ok(None)` when shut down while asking.
async fn deterministic_resume(
    bus: &Bus,
    checkpoints: Option<&CheckpointDir>,
    shutdown: Shutdown,
) -> anyhow::Result<Option<Option<agent::Checkpoint>>> {
    let Some(cut) = node::ask_cut(bus, shutdown).await? else { return Ok(None) };
    if cut.learner_step == 0 {
        if let Some(dir) = checkpoints
            && let Some(&newest) = dir.steps()?.last()
        {
            tracing::warn!(
                newest,
                "deterministic mode: the replay server has no cut to resume, so the run starts over at \
                 step 0 (give it a snapshot_path to resume)"
            );
        }
        return Ok(Some(None));
    }
    let found = checkpoints.map(|dir| dir.at(cut.learner_step)).transpose()?.flatten();
    match found {
        Some(checkpoint) => Ok(Some(Some(checkpoint))),
        None => anyhow::bail!(
            "deterministic mode: the replay server resumes at learner step {}, but there is no learner \
             checkpoint of that step ([learner] checkpoint_dir)",
            cut.learner_step
        ),
    }
}

/// Refuses to resume a checkpoint trained on other frozen levels than the run file names: its
/// policy's actions mean latents of those levels, not of these.
fn check_resumed_stack(checkpoint: &agent::Checkpoint, frozen: &Frozen) -> anyhow::Result<()> {
    let tensors =
        agent::ParamSnapshot { version: checkpoint.step, safetensors: checkpoint.safetensors.clone() }
            .tensors()?;
    let theirs = Frozen::new(PolicyStack::from_embedded(&tensors)?)?.hash;
    if theirs != frozen.hash {
        let name = proto::ContentHash::describe;
        anyhow::bail!(
            "the checkpoint at step {} was trained on {}, but [hierarchy] names {}: resume with the same levels",
            checkpoint.step,
            name(theirs),
            name(frozen.hash)
        );
    }
    Ok(())
}

/// Evaluates each (epoch, weights) it receives, keeps the best weights (with a checkpoint
/// directory) and reports the result; ends when the sender does.
fn evaluation_thread(
    mut env: Box<dyn sim::Environment>,
    mut actor: Actor,
    (episodes, mode): (u32, EvalMode),
    mut best: Option<BestPolicy>,
    requests: std::sync::mpsc::Receiver<(u64, ParamSnapshot)>,
    out: mpsc::Sender<Out>,
) {
    for (epoch, snapshot) in requests {
        let learner_step = snapshot.version;
        let result = actor
            .load(&snapshot)
            .map_err(anyhow::Error::from)
            .and_then(|()| evaluate(&mut actor, env.as_mut(), episodes, mode));
        match result {
            Ok(e) => {
                let (mean_return, std_return, mode_name) = (e.mean_return, e.std_return, mode.name());
                tracing::info!(
                    epoch,
                    learner_step,
                    episodes,
                    mode = mode_name,
                    mean_return,
                    std_return,
                    goal_success = e.goal_success,
                    "evaluation"
                );
                let report = e.report(epoch, learner_step, episodes, mode);
                match best.as_mut().map(|best| best.offer(&report, &snapshot)) {
                    Some(Ok(true)) => tracing::info!(learner_step, mean_return, "new best policy"),
                    Some(Err(error)) => tracing::error!(%error, "best policy not written"),
                    Some(Ok(false)) | None => {}
                }
                if out.blocking_send(Out::Eval(report)).is_err() {
                    return;
                }
            }
            Err(error) => tracing::error!(%error, "evaluation failed"),
        }
    }
}
