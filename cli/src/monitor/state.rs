//! The monitor's picture of a run, built from the messages it receives: sans-IO (bytes and the time
//! go in, summaries and record lines come out), so every rule is unit-tested without a bus.

use std::collections::{BTreeSet, HashMap, VecDeque};

use proto::{BarrierReport, EpisodeReport, EvalReport, GlobalStep, NodeId, Role, RunId, StatsReport, Topic};

use super::family::{Family, FamilyCounts};
use super::record::{EpisodeRecord, EvalRecord};
use super::steps::{StepCount, StepSource};
use super::tick::{BlockedEntry, ExecutorRow, Losses, Now, Tick};

/// Episodes averaged for the "recent return" figure (the plot's moving-average window too).
pub const RECENT_EPISODES: usize = 20;

/// Latest report per process, liveliness, and the recent episodes and evaluations of one run.
#[derive(Debug)]
pub struct MonitorState {
    run: RunId,
    reports: HashMap<NodeId, StatsReport>,
    alive: HashMap<NodeId, bool>,
    /// Times each process's token came back after vanishing: its restarts (a supervisor's, or a
    /// user's), or a link that dropped and came back.
    returns: HashMap<NodeId, u64>,
    barriers: HashMap<u32, BarrierReport>,
    /// Env steps per executor id, over its processes, from every report that carries them.
    env_steps: HashMap<u32, StepCount>,
    recent_returns: VecDeque<f64>,
    last_step: Option<GlobalStep>,
    last_eval: Option<EvalReport>,
    received: FamilyCounts,
    undecodable: FamilyCounts,
}

impl MonitorState {
    /// Nothing seen yet in `run`.
    pub fn new(run: RunId) -> MonitorState {
        MonitorState {
            run,
            reports: HashMap::new(),
            alive: HashMap::new(),
            returns: HashMap::new(),
            barriers: HashMap::new(),
            env_steps: HashMap::new(),
            recent_returns: VecDeque::with_capacity(RECENT_EPISODES),
            last_step: None,
            last_eval: None,
            received: FamilyCounts::default(),
            undecodable: FamilyCounts::default(),
        }
    }

    /// Decodes `payload` as `M`, counting it as received and, on failure, as undecodable.
    fn decode<M: proto::Message>(&mut self, family: Family, payload: &[u8]) -> Option<M> {
        self.received.add(family);
        match proto::decode::<M>(payload) {
            Ok(message) => Some(message),
            Err(error) => {
                tracing::debug!(%family, %error, "undecodable message");
                self.undecodable.add(family);
                None
            }
        }
    }

    /// A [`StatsReport`] from `stats/<role>/<id>`: replaces that process's previous one.
    pub fn on_stats(&mut self, payload: &[u8]) {
        if let Some(report) = self.decode::<StatsReport>(Family::Stats, payload) {
            if report.role == Role::Executor
                && let Some(steps) = report.metric("executor/env_steps")
            {
                self.observe_steps(report.id, StepSource::Stats, steps as u64);
            }
            self.reports.insert(report.node(), report);
        }
    }

    /// An [`EpisodeReport`]: returns its record line.
    pub fn on_episode(&mut self, now: Now, payload: &[u8]) -> Option<EpisodeRecord> {
        let episode = self.decode::<EpisodeReport>(Family::Episodes, payload)?;
        self.observe_steps(episode.executor_id, StepSource::Episode, episode.env_steps);
        if self.recent_returns.len() == RECENT_EPISODES {
            self.recent_returns.pop_front();
        }
        self.recent_returns.push_back(episode.episode_return);
        Some(EpisodeRecord::new(now, &episode, self.env_steps_total()))
    }

    /// An [`EvalReport`] from `eval`: returns its record line.
    pub fn on_eval(&mut self, now: Now, payload: &[u8]) -> Option<EvalRecord> {
        let eval = self.decode::<EvalReport>(Family::Eval, payload)?;
        self.last_eval = Some(eval);
        Some(EvalRecord { now, eval, env_steps_total: self.env_steps_total() })
    }

    /// A [`GlobalStep`] from `control/step`.
    pub fn on_step(&mut self, payload: &[u8]) {
        if let Some(step) = self.decode::<GlobalStep>(Family::Step, payload) {
            self.last_step = Some(step);
        }
    }

    /// A [`BarrierReport`] from the key `key` (`control/barrier/<id>`). One whose executor id is not
    /// the key's is counted as undecodable and dropped, as the param server drops it: a forged or
    /// misrouted report must not add a phantom executor row.
    pub fn on_barrier(&mut self, key: &str, payload: &[u8]) {
        let Some(report) = self.decode::<BarrierReport>(Family::Barrier, payload) else { return };
        match Topic::parse(&self.run, key) {
            Ok(Topic::ControlBarrier { executor_id }) if executor_id == report.executor_id => {
                self.observe_steps(report.executor_id, StepSource::Barrier, report.env_steps);
                self.barriers.insert(report.executor_id, report);
            }
            _ => {
                tracing::debug!(key, executor_id = report.executor_id, "barrier report not from its key");
                self.undecodable.add(Family::Barrier);
            }
        }
    }

    /// A liveliness token under `key` appeared (`alive`) or vanished.
    pub fn on_liveliness(&mut self, key: &str, alive: bool) {
        self.received.add(Family::Liveliness);
        match Topic::parse(&self.run, key) {
            Ok(Topic::Liveliness(node)) => {
                if self.alive.insert(node, alive) == Some(false) && alive {
                    *self.returns.entry(node).or_default() += 1;
                }
            }
            _ => self.undecodable.add(Family::Liveliness),
        }
    }

    /// The summary at `now`.
    pub fn tick(&self, now: Now) -> Tick {
        let executors: Vec<ExecutorRow> =
            self.executor_ids().into_iter().map(|id| self.executor_row(id)).collect();
        let running = executors.iter().filter(|row| row.alive != Some(false));
        let rates: Vec<f64> = running.filter_map(|row| row.env_steps_per_s).collect();
        let learner = |name: &str| self.role_metric(Role::Learner, name);
        Tick {
            now,
            learner_step: learner("learner/learner_step")
                .map(|s| s as u64)
                .or(self.last_step.map(|s| s.learner_step)),
            weights_version: self
                .last_step
                .map(|s| s.weights_version)
                .or(self.role_metric(Role::Param, "param/weights_version").map(|v| v as u64)),
            updates_per_s: learner("learner/updates_per_s"),
            replay_size: self.role_metric(Role::Replay, "replay/size_transitions"),
            env_steps_total: self.env_steps_total(),
            env_steps_per_s_total: (!rates.is_empty()).then(|| rates.iter().sum()),
            executors,
            losses: Losses {
                q_loss: learner("learner/q_loss"),
                v_loss: learner("learner/v_loss"),
                policy_loss: learner("learner/policy_loss"),
            },
            blocked: self.blocked(),
            undecodable: self.undecodable.clone(),
        }
    }

    fn observe_steps(&mut self, executor: u32, source: StepSource, steps: u64) {
        self.env_steps.entry(executor).or_default().observe(source, steps);
    }

    /// Every executor id seen on any topic, ascending.
    fn executor_ids(&self) -> BTreeSet<u32> {
        let executor = |node: &&NodeId| node.role == Role::Executor;
        let mut ids: BTreeSet<u32> = self.reports.keys().filter(executor).map(|n| n.id).collect();
        ids.extend(self.alive.keys().filter(executor).map(|n| n.id));
        ids.extend(self.barriers.keys());
        ids.extend(self.env_steps.keys());
        ids
    }

    fn executor_row(&self, id: u32) -> ExecutorRow {
        let node = NodeId { role: Role::Executor, id };
        let report = self.reports.get(&node);
        let metric = |name: &str| report.and_then(|r| r.metric(name));
        let barrier = self.barriers.get(&id);
        ExecutorRow {
            id,
            alive: self.alive.get(&node).copied(),
            env_steps: self.env_steps.get(&id).map(StepCount::total),
            env_steps_per_s: metric("executor/env_steps_per_s"),
            weights_lag_steps: metric("executor/weights_lag_steps"),
            policy_lag_steps: metric("executor/policy_lag_steps"),
            blocked: metric("executor/blocked").map(|b| b > 0.5).or(barrier.map(|b| b.blocked)),
            last_return: metric("executor/last_return"),
        }
    }

    fn env_steps_total(&self) -> Option<u64> {
        let known: Vec<u64> = self
            .executor_ids()
            .into_iter()
            .filter_map(|id| self.env_steps.get(&id).map(StepCount::total))
            .collect();
        (!known.is_empty()).then(|| known.iter().sum())
    }

    fn blocked(&self) -> Vec<BlockedEntry> {
        self.reports_sorted()
            .into_iter()
            .flat_map(|report| {
                let node = node_name(report.node());
                report.blocked.iter().map(move |b| BlockedEntry {
                    node: node.clone(),
                    what: b.what.clone(),
                    why: b.why.clone(),
                    since_ms: b.since_ms,
                })
            })
            .collect()
    }

    /// `name` from the lowest-id process of `role` that reports it.
    pub fn role_metric(&self, role: Role, name: &str) -> Option<f64> {
        self.reports_sorted().into_iter().filter(|r| r.role == role).find_map(|r| r.metric(name))
    }

    /// The latest report of every process: learner, replay, param server, then executors by id.
    pub fn reports_sorted(&self) -> Vec<&StatsReport> {
        let mut reports: Vec<&StatsReport> = self.reports.values().collect();
        reports.sort_by_key(|r| (role_rank(r.role), r.id));
        reports
    }

    /// How often `node`'s token came back after vanishing (restarts, or links lost and found).
    pub fn returns(&self, node: NodeId) -> u64 {
        self.returns.get(&node).copied().unwrap_or(0)
    }

    /// Returns of every process together.
    pub fn returns_total(&self) -> u64 {
        self.returns.values().sum()
    }

    /// Whether `node`'s liveliness token is up (`None`: never seen).
    pub fn is_alive(&self, node: NodeId) -> Option<bool> {
        self.alive.get(&node).copied()
    }

    /// Mean return of the last [`RECENT_EPISODES`] episodes, and how many that is.
    pub fn recent_return(&self) -> Option<RecentReturn> {
        let count = self.recent_returns.len();
        (count > 0)
            .then(|| RecentReturn { mean: self.recent_returns.iter().sum::<f64>() / count as f64, count })
    }

    /// The run being watched.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// The newest global step announced.
    pub fn last_step(&self) -> Option<GlobalStep> {
        self.last_step
    }

    /// The newest evaluation.
    pub fn last_eval(&self) -> Option<EvalReport> {
        self.last_eval
    }

    /// Messages received, per family.
    pub fn received(&self) -> &FamilyCounts {
        &self.received
    }

    /// Messages that did not decode, per family.
    pub fn undecodable(&self) -> &FamilyCounts {
        &self.undecodable
    }
}

/// The mean of the recent episodes' returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecentReturn {
    /// Mean return.
    pub mean: f64,
    /// Episodes averaged (at most [`RECENT_EPISODES`]).
    pub count: usize,
}

/// `<role>/<id>`, as in the topic keys.
pub fn node_name(node: NodeId) -> String {
    format!("{}/{}", node.role, node.id)
}

/// Display order of the roles: the learner first, executors (many) last.
fn role_rank(role: Role) -> u8 {
    match role {
        Role::Learner => 0,
        Role::Replay => 1,
        Role::Param => 2,
        Role::Executor => 3,
    }
}

#[cfg(test)]
mod tests;
