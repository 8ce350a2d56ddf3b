//! The rollout thread: steps while the barrier allows, waits (with a reason and a deadline) when it
//! does not, loads new weights between steps, and hands everything to publish to the async shell.

use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::ParamSnapshot;
use proto::{BarrierReport, EpisodeReport, ExperienceBatch, GlobalStep};
use tokio::sync::{mpsc, watch};

use crate::ExecutorSettings;
use crate::inbox::Inbox;
use crate::rollout::Rollout;
use crate::spool::MadeMark;

/// Why the rollout is not stepping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// No global step announced yet (param server not seen).
    NoGlobalStep,
    /// No weights loaded yet.
    NoWeights,
    /// Deterministic mode: the next step must act with this exact version, not yet fetched.
    ExactWeights {
        /// The version the step needs.
        want: u64,
    },
    /// Its weights are older than the lag bound allows.
    StaleWeights {
        /// Version held.
        have: u64,
        /// Oldest allowed.
        min: u64,
    },
    /// It used its allowance and no announcement has come for a while: the param server is silent.
    ParamServerSilent {
        /// Seconds since the last announcement.
        silent_s: u64,
    },
    /// It used its allowance; the learner must step first.
    Barrier {
        /// Its env steps.
        env_steps: u64,
        /// The allowance.
        allowed: u64,
        /// The learner step it is at.
        learner_step: u64,
    },
}

impl Wait {
    /// What waits, as a metric-style name.
    pub fn what(&self) -> &'static str {
        match self {
            Wait::NoGlobalStep | Wait::ParamServerSilent { .. } => "executor/global_step",
            Wait::NoWeights | Wait::StaleWeights { .. } | Wait::ExactWeights { .. } => "executor/weights",
            Wait::Barrier { .. } => "executor/barrier",
        }
    }

    /// Why, in words.
    pub fn why(&self) -> String {
        match self {
            Wait::NoGlobalStep => "no global step announced yet: is the param server up?".into(),
            Wait::NoWeights => "waiting for the first weights from the param server".into(),
            Wait::ParamServerSilent { silent_s } => {
                format!(
                    "at the barrier, and no global step announced for {silent_s} s: is the param server up?"
                )
            }
            Wait::ExactWeights { want } => {
                format!("deterministic mode: the next step acts with weights version {want}, not fetched yet")
            }
            Wait::StaleWeights { have, min } => {
                format!("weights version {have} is older than the allowed {min}")
            }
            Wait::Barrier { env_steps, allowed, learner_step } => {
                format!(
                    "env steps {env_steps} reached the allowance {allowed} at learner step {learner_step}"
                )
            }
        }
    }
}

/// What the rollout waits on, and since when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waiting {
    /// The reason.
    pub wait: Wait,
    /// Since when (for durations).
    pub since: Instant,
    /// Since when, Unix ms (for reports).
    pub since_ms: u64,
}

/// A progress snapshot for the stats report.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Cumulative env steps.
    pub env_steps: u64,
    /// Env steps per second since the previous snapshot.
    pub env_steps_per_s: f64,
    /// Episodes finished.
    pub episodes: u64,
    /// Return of the last finished episode.
    pub last_return: Option<f64>,
    /// Loaded weights' version.
    pub weights_version: Option<u64>,
    /// The newest announcement seen.
    pub step: Option<GlobalStep>,
    /// The allowance now.
    pub allowed_env_steps: u64,
    /// Weight loads so far.
    pub weights_loads: u64,
    /// Snapshots that could not be loaded (kept acting with the previous weights).
    pub weights_unloadable: u64,
    /// Batches handed to the shell.
    pub batches: u64,
    /// Non-finite steps dropped.
    pub dropped_non_finite: u64,
    /// Steps that start no n-step transition (the tail before a truncation; `[agent] n_step` > 1).
    pub dropped_n_step_tail: u64,
    /// Total time spent waiting, ms.
    pub blocked_ms_total: u64,
    /// What it waits on now, and since when.
    pub waiting: Option<Waiting>,
}

/// What the thread sends the shell.
#[derive(Debug)]
pub enum Out {
    /// A batch for the replay server.
    Experience(ExperienceBatch),
    /// A finished episode.
    Episode(EpisodeReport),
    /// The barrier state.
    Barrier(BarrierReport),
    /// Progress for the stats report.
    Progress(Box<Progress>),
}

/// What the thread did, when it stops.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WorkerReport {
    /// Env steps taken.
    pub env_steps: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Batches handed to the shell.
    pub batches: u64,
    /// Weight loads (the first one included); each is a newer version than the last (the inbox and
    /// the fetch task only pass newer ones on), so this is also the number of versions acted with.
    pub weights_loads: u64,
    /// Snapshots that could not be loaded; the worker went on with the weights it had.
    pub weights_unloadable: u64,
    /// Non-finite steps dropped.
    pub dropped_non_finite: u64,
    /// Steps that start no n-step transition (the tail before a truncation; `[agent] n_step` > 1).
    pub dropped_n_step_tail: u64,
    /// Total time waiting, ms.
    pub blocked_ms_total: u64,
    /// Largest `env_steps − allowance` seen after any step; never positive when the barrier holds.
    pub max_over_allowance: i64,
    /// Transitions made (that joined the pending batch), all published by the time it stops.
    pub transitions: u64,
    /// Steps whose transitions could not be added to the spool's made mark (its disk failed).
    pub made_mark_failed: u64,
}

struct Worker {
    id: u32,
    /// Deterministic mode: the schedule, where the exact version wanted is posted for the fetch
    /// task, and a fetched version not yet due (it is loaded at its block's start).
    lockstep: Option<Lockstep>,
    /// Env steps covered by the last batch handed over (deterministic mode's block-end marker).
    sent_through: u64,
    rollout: Rollout,
    /// Durable experience: the transitions made, marked on disk before they can reach a batch.
    made: Option<MadeMark>,
    inbox: Arc<Inbox>,
    out: mpsc::Sender<Out>,
    settings: ExecutorSettings,
    report: WorkerReport,
    joined_at: Option<u64>,
    step: Option<GlobalStep>,
    allowed: u64,
    waiting: Option<Waiting>,
    last_return: Option<f64>,
    heard_at: Option<Instant>,
    /// Counts unloadable snapshots and rate-limits their warnings.
    rejects: node::Rejects,
}

/// Deterministic mode's part of the rollout thread.
pub struct Lockstep {
    /// The schedule.
    pub schedule: run::Lockstep,
    /// The run's seed, for the streams' restart at each cut.
    pub seed: u64,
    /// The version the next step needs, for the fetch task.
    pub wanted: watch::Sender<Option<u64>>,
    /// A fetched version, kept until its block starts.
    pub staged: Option<ParamSnapshot>,
}

/// Runs the rollout until the inbox says stop (or the shell goes away); errors end it early. With
/// `made`, every step's new transitions are added to it before they can reach a batch.
pub fn run(
    id: u32,
    rollout: Rollout,
    inbox: Arc<Inbox>,
    out: mpsc::Sender<Out>,
    settings: ExecutorSettings,
    lockstep: Option<Lockstep>,
    made: Option<MadeMark>,
) -> anyhow::Result<WorkerReport> {
    let mut w = Worker {
        id,
        lockstep,
        sent_through: 0,
        rollout,
        made,
        inbox,
        out,
        settings,
        report: WorkerReport { max_over_allowance: i64::MIN, ..WorkerReport::default() },
        joined_at: None,
        step: None,
        allowed: 0,
        waiting: None,
        last_return: None,
        heard_at: None,
        rejects: node::Rejects::default(),
    };
    w.run()?;
    Ok(w.report)
}

impl Worker {
    fn send(&self, message: Out) -> bool {
        // Blocks when the shell is behind: publishing is the executor's back-pressure.
        self.out.blocking_send(message).is_ok()
    }

    fn run(&mut self) -> anyhow::Result<()> {
        let report_every = Duration::from_millis(self.settings.report_interval_ms);
        let stats_every = Duration::from_millis(self.settings.stats_interval_ms);
        let deadline = Duration::from_millis(self.settings.wait_deadline_ms);
        let (mut last_report, mut last_stats) = (Instant::now(), Instant::now());
        let mut steps_at_stats = 0;
        let mut last_warn = None;
        loop {
            let taken = self.inbox.take();
            let (step, weights, generation) = (taken.step, taken.weights, taken.generation);
            self.heard_at = taken.heard_at;
            if taken.stop {
                break;
            }
            if let Some(snapshot) = weights {
                match self.lockstep.as_mut() {
                    Some(lockstep) => lockstep.staged = Some(snapshot),
                    None => self.load(&snapshot),
                }
            }
            self.step = step;
            let wait = match self.lockstep.as_ref().map(|l| l.schedule) {
                Some(schedule) => self.check_lockstep(schedule),
                None => self.check(),
            };
            match wait {
                None => {
                    if let Some(waiting) = self.waiting.take() {
                        self.report.blocked_ms_total += waiting.since.elapsed().as_millis() as u64;
                        self.send_report();
                    }
                    self.step_once()?;
                }
                Some(wait) => {
                    // Publish what is pending first: the learner may be waiting for exactly these.
                    self.flush()?;
                    // A change of reason keeps the time the wait began.
                    let (since, since_ms) = self
                        .waiting
                        .map_or_else(|| (Instant::now(), node::unix_ms()), |w| (w.since, w.since_ms));
                    let newly = self.waiting.is_none_or(|w| w.wait != wait);
                    self.waiting = Some(Waiting { wait, since, since_ms });
                    if newly {
                        self.send_report();
                    }
                    let waited = since.elapsed();
                    if waited >= deadline && last_warn.is_none_or(|at: Instant| at.elapsed() >= deadline) {
                        last_warn = Some(Instant::now());
                        let waited_ms = waited.as_millis() as u64;
                        tracing::warn!(what = wait.what(), why = %wait.why(), waited_ms, "still waiting");
                    }
                    self.inbox.wait_for_change(generation, report_every);
                }
            }
            if last_report.elapsed() >= report_every {
                last_report = Instant::now();
                if !self.send_report() {
                    break;
                }
            }
            if last_stats.elapsed() >= stats_every {
                let seconds = last_stats.elapsed().as_secs_f64();
                last_stats = Instant::now();
                let env_steps = self.rollout.env_steps();
                let rate = (env_steps - steps_at_stats) as f64 / seconds;
                steps_at_stats = env_steps;
                if !self.send(Out::Progress(Box::new(self.progress(rate)))) {
                    break;
                }
            }
        }
        self.flush()?;
        self.report.env_steps = self.rollout.env_steps();
        if let Some(waiting) = self.waiting.take() {
            self.report.blocked_ms_total += waiting.since.elapsed().as_millis() as u64;
        }
        Ok(())
    }

    /// Loads `snapshot`. Bad weights (a corrupt or forged frame, wrong shapes, non-finite values)
    /// never stop the executor: it keeps acting with the weights it has (the load is all or nothing)
    /// and the fetch task waits for a newer version.
    fn load(&mut self, snapshot: &ParamSnapshot) {
        match self.rollout.load(snapshot) {
            Ok(()) => self.report.weights_loads += 1,
            Err(error) => {
                self.report.weights_unloadable += 1;
                let detail = format!("version {}: {error}", snapshot.version);
                self.rejects.record("weights/unloadable", &detail, Instant::now());
            }
        }
    }

    /// Deterministic mode's [`Worker::check`]: the allowance is the schedule's, and each step acts
    /// with exactly the version the schedule names (asked of the fetch task in advance).
    fn check_lockstep(&mut self, schedule: run::Lockstep) -> Option<Wait> {
        let Some(step) = self.step else { return Some(Wait::NoGlobalStep) };
        self.joined_at.get_or_insert(0);
        self.allowed = schedule.allowance(step.learner_step);
        let env_steps = self.rollout.env_steps();
        let want = schedule.weights_for(env_steps);
        if let Some(lockstep) = &self.lockstep {
            lockstep.wanted.send_if_modified(|v| v.replace(want) != Some(want));
        }
        if env_steps >= self.allowed {
            return Some(self.at_barrier(env_steps, step));
        }
        if self.rollout.weights_version() != Some(want) {
            let staged = self.lockstep.as_mut().and_then(|l| l.staged.take_if(|s| s.version == want));
            match staged {
                Some(snapshot) => self.load(&snapshot),
                None => return Some(Wait::ExactWeights { want }),
            }
        }
        None
    }

    /// The wait at the barrier, or a silent param server's when it has said nothing for long.
    fn at_barrier(&self, env_steps: u64, step: GlobalStep) -> Wait {
        let silent = self.heard_at.map_or(Duration::ZERO, |at| at.elapsed());
        if silent >= Duration::from_millis(self.settings.wait_deadline_ms) {
            return Wait::ParamServerSilent { silent_s: silent.as_secs() };
        }
        Wait::Barrier { env_steps, allowed: self.allowed, learner_step: step.learner_step }
    }

    /// Whether the rollout may step now, and if not, why.
    fn check(&mut self) -> Option<Wait> {
        let Some(step) = self.step else { return Some(Wait::NoGlobalStep) };
        let joined_at = *self.joined_at.get_or_insert(step.learner_step);
        // Never shrinks: a newcomer shrinks the warm-up share, but what was granted stays granted.
        self.allowed = self.allowed.max(step.allowance(joined_at));
        let Some(version) = self.rollout.weights_version() else { return Some(Wait::NoWeights) };
        if version < step.min_weights_version {
            return Some(Wait::StaleWeights { have: version, min: step.min_weights_version });
        }
        let env_steps = self.rollout.env_steps();
        if env_steps >= self.allowed {
            return Some(self.at_barrier(env_steps, step));
        }
        None
    }

    fn step_once(&mut self) -> anyhow::Result<()> {
        // Deterministic mode: the last step of a checkpoint's block ends the episode.
        let cut = self.lockstep.as_ref().and_then(|l| l.schedule.cut_ending_at(self.rollout.env_steps() + 1));
        if cut.is_some() {
            self.rollout.truncate_next_step();
        }
        let pending = self.rollout.pending();
        let outcome = self.rollout.step()?;
        self.mark_made(self.rollout.pending().saturating_sub(pending) as u64);
        let over = self.rollout.env_steps() as i64 - self.allowed as i64;
        self.report.max_over_allowance = self.report.max_over_allowance.max(over);
        if outcome.dropped_non_finite {
            self.report.dropped_non_finite += 1;
            tracing::warn!("non-finite observation or reward: transition dropped, episode reset");
        }
        self.report.dropped_n_step_tail += outcome.dropped_n_step_tail as u64;
        if let Some(episode) = outcome.episode {
            self.report.episodes += 1;
            self.last_return = Some(episode.episode_return);
            self.flush()?;
            self.send(Out::Episode(episode));
        } else if self.rollout.pending() >= self.settings.batch_transitions as usize {
            self.flush()?;
        }
        if let Some((schedule, seed)) = self.lockstep.as_ref().map(|l| (l.schedule, l.seed)) {
            // At a block's end everything of the block goes out, and the replay server learns that
            // the block is complete even when its last steps made no transition.
            let env_steps = self.rollout.env_steps();
            if env_steps == schedule.block_end(schedule.block_of(env_steps - 1)) {
                self.flush()?;
                if self.sent_through < env_steps {
                    let marker = self.rollout.marker();
                    self.sent_through = marker.env_steps;
                    self.send(Out::Experience(marker));
                }
            }
            if let Some(at) = cut {
                self.rollout.restart_streams(run::Lockstep::cut_seed(seed, self.id, at));
            }
        }
        Ok(())
    }

    /// Counts `transitions` just made, on disk first when durable (before any can reach a batch). A
    /// failed mark is counted and logged once; the audit then finds the stream's ledger past its
    /// mark and says so.
    fn mark_made(&mut self, transitions: u64) {
        self.report.transitions += transitions;
        let Some(made) = self.made.as_mut().filter(|_| transitions > 0) else { return };
        if let Err(error) = made.add(transitions) {
            if self.report.made_mark_failed == 0 {
                tracing::error!(%error, "could not mark the transitions made in the spool");
            }
            self.report.made_mark_failed += 1;
        }
    }

    /// Publishes every pending transition, in batches of at most `batch_transitions`.
    fn flush(&mut self) -> anyhow::Result<()> {
        while let Some(batch) = self.rollout.flush(self.settings.batch_transitions as usize)? {
            self.report.batches += 1;
            self.sent_through = batch.env_steps;
            self.send(Out::Experience(batch));
        }
        Ok(())
    }

    fn send_report(&self) -> bool {
        let step = self.step;
        self.send(Out::Barrier(BarrierReport {
            executor_id: self.id,
            env_steps: self.rollout.env_steps(),
            allowed_env_steps: self.allowed,
            learner_step_seen: step.map_or(0, |s| s.learner_step),
            joined_at: self.joined_at.unwrap_or(0),
            weights_version: self.rollout.weights_version().unwrap_or(0),
            blocked: self.waiting.is_some(),
            blocked_ms_total: self.blocked_ms_total_now(),
        }))
    }

    fn blocked_ms_total_now(&self) -> u64 {
        self.report.blocked_ms_total + self.waiting.map_or(0, |w| w.since.elapsed().as_millis() as u64)
    }

    fn progress(&self, env_steps_per_s: f64) -> Progress {
        Progress {
            env_steps: self.rollout.env_steps(),
            env_steps_per_s,
            episodes: self.report.episodes,
            last_return: self.last_return,
            weights_version: self.rollout.weights_version(),
            step: self.step,
            allowed_env_steps: self.allowed,
            weights_loads: self.report.weights_loads,
            weights_unloadable: self.report.weights_unloadable,
            batches: self.report.batches,
            dropped_non_finite: self.report.dropped_non_finite,
            dropped_n_step_tail: self.report.dropped_n_step_tail,
            blocked_ms_total: self.blocked_ms_total_now(),
            waiting: self.waiting,
        }
    }
}

#[cfg(test)]
mod tests {
    use agent::{Actor, AgentConfig, Learner};
    use sim::Task;

    use super::*;

    fn step(learner_step: u64, share: u64) -> GlobalStep {
        GlobalStep {
            learner_step,
            weights_version: 0,
            env_steps_per_learner_step: 2,
            warm_up_share: share,
            min_weights_version: 0,
            live_executors: 1,
        }
    }

    /// Receives until a barrier report satisfies `pred`, collecting everything else; fails after
    /// a minute without one.
    fn until(rx: &mut mpsc::Receiver<Out>, pred: impl Fn(&BarrierReport) -> bool) -> (BarrierReport, u64) {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut transitions = 0;
        loop {
            match rx.try_recv() {
                Ok(Out::Barrier(r)) if pred(&r) => return (r, transitions),
                Ok(Out::Experience(b)) => transitions += b.len() as u64,
                Ok(_) => {}
                Err(mpsc::error::TryRecvError::Empty) => {
                    assert!(Instant::now() < deadline, "no matching barrier report within a minute");
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(mpsc::error::TryRecvError::Disconnected) => panic!("the worker hung up"),
            }
        }
    }

    /// A worker on the pendulum with tiny networks, running on its own thread.
    struct Running {
        cfg: AgentConfig,
        inbox: Arc<Inbox>,
        rx: mpsc::Receiver<Out>,
        worker: std::thread::JoinHandle<anyhow::Result<WorkerReport>>,
    }

    fn start() -> Running {
        start_marking(None)
    }

    fn start_marking(made: Option<MadeMark>) -> Running {
        let env = sim::make(Task::InvertedPendulum, 1).unwrap();
        let cfg = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            ..AgentConfig::for_task(env.spec().obs_dim, env.spec().act_dim)
        };
        let rollout = Rollout::new(0, env, Actor::new(cfg.clone(), 2).unwrap(), 1);
        let inbox = Arc::new(Inbox::default());
        let (tx, rx) = mpsc::channel(1024);
        let settings =
            ExecutorSettings { batch_transitions: 4, report_interval_ms: 10, ..ExecutorSettings::default() };
        let worker = {
            let inbox = inbox.clone();
            std::thread::spawn(move || run(0, rollout, inbox, tx, settings, None, made))
        };
        Running { cfg, inbox, rx, worker }
    }

    #[test]
    fn steps_exactly_to_the_allowance_then_waits_for_the_learner() {
        let Running { cfg, inbox, mut rx, worker } = start();
        let weights = Learner::new(cfg, 1).unwrap().snapshot().unwrap();
        // No step, no weights: it waits without stepping.
        let (first, _) = until(&mut rx, |r| r.blocked);
        assert_eq!(first.env_steps, 0);
        inbox.set_step(step(10, 5));
        inbox.set_weights(weights);
        // Joined at learner step 10 with a share of 5: exactly 5 steps, all published, then it waits.
        let (at_share, sent) = until(&mut rx, |r| r.blocked && r.env_steps > 0);
        assert_eq!((at_share.env_steps, at_share.allowed_env_steps, at_share.joined_at), (5, 5, 10));
        assert_eq!(sent, 5, "pending transitions are flushed before waiting");
        // Three learner steps at k = 2 allow six more.
        inbox.set_step(step(13, 5));
        let (next, sent) = until(&mut rx, |r| r.blocked && r.env_steps > 5);
        assert_eq!((next.env_steps, next.allowed_env_steps, sent), (11, 11, 6));
        // A newcomer shrinks the share; what was granted stays granted, and nothing more is taken.
        inbox.set_step(GlobalStep { warm_up_share: 2, live_executors: 2, ..step(13, 5) });
        inbox.stop();
        let report = worker.join().unwrap().unwrap();
        assert_eq!(report.env_steps, 11);
        assert_eq!(report.max_over_allowance, 0);
        assert_eq!(report.weights_loads, 1);
    }

    #[test]
    fn unloadable_weights_are_counted_and_acting_goes_on_with_the_old_ones() {
        let Running { cfg, inbox, mut rx, worker } = start();
        let weights =
            agent::ParamSnapshot { version: 3, ..Learner::new(cfg.clone(), 1).unwrap().snapshot().unwrap() };
        let wrong_shapes = AgentConfig { critic_hidden: vec![5], ..cfg };
        let wrong_shapes =
            agent::ParamSnapshot { version: 7, ..Learner::new(wrong_shapes, 1).unwrap().snapshot().unwrap() };
        let corrupt = agent::ParamSnapshot { version: 5, safetensors: vec![0xff; 64] };
        inbox.set_step(step(10, 5));
        inbox.set_weights(weights);
        until(&mut rx, |r| r.blocked && r.env_steps == 5);
        // Each bad snapshot arrives with one more learner step: the worker must take that step with
        // the weights it had, whatever the snapshot held.
        for (k, bad) in [corrupt, wrong_shapes].into_iter().enumerate() {
            inbox.set_weights(bad);
            inbox.set_step(step(11 + k as u64, 5));
            let (r, _) = until(&mut rx, |r| r.blocked && r.env_steps == 7 + 2 * k as u64);
            assert_eq!(r.weights_version, 3, "still acting with version 3");
        }
        inbox.stop();
        let report = worker.join().unwrap().unwrap();
        assert_eq!((report.weights_loads, report.weights_unloadable, report.env_steps), (1, 2, 9));
    }

    #[test]
    fn every_transition_made_is_marked_before_it_is_sent() {
        let dir = tempfile::tempdir().unwrap();
        let spool = crate::Spool::open(dir.path(), 0, 1 << 20).unwrap();
        let Running { cfg, inbox, mut rx, worker } = start_marking(Some(spool.made_mark(9).unwrap()));
        let made = || crate::read_ledger(dir.path(), 0).unwrap().made[&9];
        inbox.set_step(step(10, 5));
        inbox.set_weights(Learner::new(cfg, 1).unwrap().snapshot().unwrap());
        let (_, sent) = until(&mut rx, |r| r.blocked && r.env_steps == 5);
        assert_eq!((sent, made()), (5, 5));
        // Mid-run, whatever has been sent is marked already; the rest is in memory.
        inbox.set_step(step(200, 5));
        let (_, sent) = until(&mut rx, |r| r.env_steps >= 100);
        assert!(made() >= 5 + sent, "{} made, {} sent", made(), 5 + sent);
        inbox.stop();
        let mut rest = 0;
        while let Some(out) = rx.blocking_recv() {
            if let Out::Experience(b) = out {
                rest += b.len() as u64;
            }
        }
        let report = worker.join().unwrap().unwrap();
        assert_eq!(report.transitions, 5 + sent + rest, "every transition made was sent");
        assert_eq!((made(), report.made_mark_failed), (report.transitions, 0));
    }
}
