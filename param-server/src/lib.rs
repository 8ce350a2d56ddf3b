//! The parameter server: holds the latest weights keyed by the global step, announces each new step
//! and weights version, and owns the executors' barrier. `run` is the whole role, so the binary and
//! the in-process test harness share it.
//!
//! # Keys (under `rl/<run>/`)
//!
//! | key                          | direction | message                                                 |
//! |------------------------------|-----------|---------------------------------------------------------|
//! | `params/publish`             | in        | `WeightsSnapshot` from the learner                      |
//! | `params/stream`              | out       | each accepted `WeightsSnapshot`, once                   |
//! | `params/weights` (queryable) | out       | the latest `WeightsSnapshot` (error reply before one exists) |
//! | `params/frozen` (queryable)  | out       | `FrozenLevels`: a hierarchy's frozen levels, from `[hierarchy]` |
//! | `control/learner`            | in        | `LearnerStep`: the learner's progress                   |
//! | `control/barrier/*`          | in        | `BarrierReport` from each executor                      |
//! | `liveliness/executor/*`      | in        | executors joining and dying                             |
//! | `control/step`               | out       | `GlobalStep` on every change and every `announce_interval_ms` |
//! | `stats/param/<id>`           | out       | `StatsReport`: the barrier per executor, what blocks    |
//!
//! # Layout
//!
//! | file            | what                                                                  |
//! |-----------------|-----------------------------------------------------------------------|
//! | `barrier.rs`    | [`Barrier`]: the global-step barrier, sans-IO                         |
//! | `store.rs`      | [`ParamStore`]: the latest weights, versions only move forward        |
//! | `starvation.rs` | [`StarvationWatch`]: when a starved learner and full barrier deadlock |
//! | `state.rs`      | [`State`]: barrier + store + counters, messages in, announcements out |
//! | `step_guard.rs` | [`StepGuard`]: refuses learner steps that jump implausibly far        |
//! | `config.rs`     | [`ParamServerConfig`] (`[param_server]`)                              |
//!
//! Every accepted version is pushed once on `params/stream`: with executors as clients of their
//! host's zenoh router, one copy crosses to each host whatever the number of executors there, so the
//! param server's outgoing bytes do not grow with them (`deploy/scale.sh` measures it). Executors
//! ask the queryable only for what a push cannot give: the current weights when they join, a version
//! whose push did not come (dropped under congestion, a partition), an exact version in
//! deterministic mode. Nobody polls.
#![deny(missing_docs)]

mod barrier;
mod body;
mod config;
mod starvation;
mod state;
mod step_guard;
mod store;

use std::time::{Duration, Instant};

pub use barrier::{Barrier, BarrierRule};
pub use body::{BadBody, Schema, check_body};
pub use config::ParamServerConfig;
use node::{Bus, Delivery, Shutdown};
use proto::{Role, Topic, TopicSet, topics};
pub use starvation::{REFILL_AFTER, StarvationWatch};
pub use state::{State, StateCounts};
pub use step_guard::{DEFAULT_MAX_LEARNER_STEPS_PER_S, Implausible, StepGuard};
pub use store::{ParamStore, Rejected, StoreCounts};
use zenoh::sample::SampleKind;

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
    /// The newest weights version held at shutdown.
    pub weights_version: u64,
    /// The global step at shutdown.
    pub learner_step: u64,
    /// Counters.
    pub counts: StateCounts,
    /// Rejected messages by `<input>/<reason>`.
    pub rejected: std::collections::BTreeMap<String, u64>,
}

/// Runs the param-server until `shutdown` fires.
pub async fn run(config: ParamServerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = Instant::now();
    let run = bus.run().clone();
    let queue = node::DEFAULT_QUEUE;
    let publish_sub = bus.subscribe(Topic::ParamsPublish, queue).await?;
    let learner_sub = bus.subscribe(Topic::ControlLearner, queue).await?;
    let barrier_sub = bus.subscribe(TopicSet::Barriers, queue).await?;
    let live_sub = bus.watch(Role::Executor).await?;
    let weights_key = topics::params_weights(&run);
    let queryable = bus.queryable(Topic::ParamsWeights, queue).await?;
    let frozen_key = topics::params_frozen(&run);
    let frozen_queryable = bus.queryable(Topic::ParamsFrozen, queue).await?;
    let frozen = frozen_levels(&config.hierarchy)?;
    let step_pub = bus.publisher(Topic::ControlStep, Delivery::Express).await?;
    // Dropped rather than blocking under congestion: one slow or cut-off host must not stall the
    // barrier, and an executor that misses a push asks for the version instead.
    let stream_pub = bus.publisher(Topic::ParamsStream, Delivery::Express).await?;
    // Declared last: seeing the token means every input above is in place.
    let _alive = bus.announce().await?;
    tracing::info!(rule = ?config.rule(), "param-server up");

    let mut state = State::new(config.rule()).with_step_guard(StepGuard::new(config.max_learner_steps_per_s));
    match config.weights_schema() {
        Some(schema) => {
            tracing::info!(tensors = schema.len(), "weights checked against the run's networks");
            state = state.with_schema(schema);
        }
        None => tracing::warn!(
            "no networks configured: the weights schema is taken from the first frame accepted, so a \
             forged frame arriving before the learner's would pin it"
        ),
    }
    if let Some((hash, _)) = &frozen {
        tracing::info!(levels = config.hierarchy.depth(), content_hash = %hash, "serving frozen levels");
        state = state.with_stack(*hash);
    }
    let frozen_reply = frozen.map(|(_, message)| zenoh::bytes::ZBytes::from(proto::encode(&message)));
    let mut held = Held::default();
    let mut announce = tokio::time::interval(Duration::from_millis(config.announce_interval_ms));
    let mut stats = tokio::time::interval(Duration::from_millis(config.stats_interval_ms));
    loop {
        let changed = tokio::select! {
            _ = shutdown.wait() => break,
            Ok(sample) = publish_sub.recv() => {
                let accepted = state.on_weights(&sample.payload().to_bytes());
                if accepted {
                    // The received frame is exactly what the queryable serves: keep it, no re-encode.
                    if let Some(version) = state.latest_version() {
                        held.take(version, sample.payload().clone());
                        // Before the announcement below, so the push is on its way when executors
                        // learn of the version.
                        match stream_pub.put(sample.payload().clone()).await {
                            Ok(()) => state.pushed(sample.payload().len()),
                            Err(error) => tracing::debug!(%error, "weights push failed"),
                        }
                    }
                }
                accepted
            }
            Ok(sample) = learner_sub.recv() => state.on_learner_step(&sample.payload().to_bytes()),
            Ok(sample) = barrier_sub.recv() => {
                let id = match Topic::parse(&run, sample.key_expr().as_str()) {
                    Ok(Topic::ControlBarrier { executor_id }) => Some(executor_id),
                    _ => None,
                };
                state.on_barrier_report(id, &sample.payload().to_bytes());
                false
            }
            Ok(sample) = live_sub.recv() => match Topic::parse(&run, sample.key_expr().as_str()) {
                Ok(Topic::Liveliness(node)) if node.role == Role::Executor => {
                    state.on_liveliness(node.id, sample.kind() == SampleKind::Put)
                }
                _ => false,
            },
            Ok(query) = queryable.recv() => {
                let (reply, bytes) = match held.serve(query.parameters().get(topics::WEIGHTS_VERSION_PARAMETER)) {
                    Ok(frame) => (query.reply(&weights_key, frame.clone()).express(true).await, frame.len()),
                    Err(why) => (query.reply_err(why).await, 0),
                };
                if let Err(error) = reply {
                    tracing::debug!(%error, "weights reply failed");
                }
                state.served(bytes);
                false
            }
            Ok(query) = frozen_queryable.recv() => {
                let reply = match &frozen_reply {
                    Some(bytes) => query.reply(&frozen_key, bytes.clone()).await,
                    None => query.reply_err("this run has no [hierarchy]: no frozen levels").await,
                };
                if let Err(error) = reply {
                    tracing::debug!(%error, "frozen levels reply failed");
                }
                false
            }
            _ = announce.tick() => {
                state.break_starvation();
                true
            }
            _ = stats.tick() => {
                if let Err(error) = bus.put_stats(&state.stats(bus.node(), node::unix_ms())).await {
                    tracing::debug!(%error, "stats not published");
                }
                false
            }
        };
        if changed {
            let step = state.announcement();
            if let Err(error) = step_pub.put_message(&step).await {
                tracing::debug!(%error, "announcement not published");
            }
        }
        // The arms above are short, but a flood of reports must not starve the timers.
        tokio::task::yield_now().await;
    }
    let report = Report {
        uptime_s: started.elapsed().as_secs_f64(),
        weights_version: state.announcement().weights_version,
        learner_step: state.announcement().learner_step,
        counts: state.counts(),
        rejected: state.rejects().counts().clone(),
    };
    drop((
        publish_sub,
        learner_sub,
        barrier_sub,
        live_sub,
        queryable,
        frozen_queryable,
        step_pub,
        stream_pub,
    ));
    bus.close().await?;
    Ok(report)
}

/// The newest weights frame and the one before it, as received. Deterministic mode's executors ask
/// for an exact version, and the learner may publish the next while an executor still needs this
/// one (`run::lockstep`), never two ahead.
#[derive(Debug, Default)]
struct Held {
    latest: Option<(u64, zenoh::bytes::ZBytes)>,
    previous: Option<(u64, zenoh::bytes::ZBytes)>,
}

impl Held {
    fn take(&mut self, version: u64, frame: zenoh::bytes::ZBytes) {
        self.previous = self.latest.replace((version, frame));
    }

    /// The frame of `version` (the newest without one), or why there is none.
    fn serve(&self, version: Option<&str>) -> Result<&zenoh::bytes::ZBytes, String> {
        let Some((newest, frame)) = &self.latest else { return Err("no weights published yet".into()) };
        let Some(wanted) = version else { return Ok(frame) };
        let wanted: u64 = wanted.parse().map_err(|_| format!("bad version parameter {wanted:?}"))?;
        [&self.latest, &self.previous]
            .into_iter()
            .flatten()
            .find(|(v, _)| *v == wanted)
            .map(|(_, frame)| frame)
            .ok_or_else(|| format!("version {wanted} is not held (newest {newest})"))
    }
}

/// The frozen levels named by `[hierarchy]`, read and checked (they must chain), with their
/// content hash; `None` for a single-level run.
pub fn frozen_levels(
    hierarchy: &run::HierarchyKeys,
) -> anyhow::Result<Option<(proto::ContentHash, proto::FrozenLevels)>> {
    if hierarchy.depth() == 0 {
        return Ok(None);
    }
    let stack = agent::PolicyStack::from_weights(&hierarchy.read().map_err(anyhow::Error::msg)?)?;
    let content_hash = proto::ContentHash(stack.content_hash()?);
    let levels =
        stack.weights().into_iter().map(|w| proto::FrozenLevel { safetensors: w.to_vec() }).collect();
    Ok(Some((content_hash, proto::FrozenLevels { content_hash, levels })))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_newest_and_the_one_before_are_served_by_version() {
        let mut held = Held::default();
        assert_eq!(held.serve(None).unwrap_err(), "no weights published yet");
        for version in [0, 500, 1000] {
            held.take(version, zenoh::bytes::ZBytes::from(vec![version as u8]));
        }
        let byte = |r: Result<&zenoh::bytes::ZBytes, String>| r.map(|b| b.to_bytes()[0]);
        assert_eq!(byte(held.serve(None)), Ok(1000u64 as u8));
        assert_eq!(byte(held.serve(Some("500"))), Ok(500u64 as u8));
        assert_eq!(byte(held.serve(Some("0"))).unwrap_err(), "version 0 is not held (newest 1000)");
        assert!(held.serve(Some("x")).unwrap_err().contains("bad version"));
    }
}
