//! The update thread: takes prefetched batches, runs SAC-LSP updates, and emits what the bus needs:
//! priority updates, the learner step, weights every M updates, an evaluation request per epoch and
//! checkpoints every K epochs. It never touches the bus itself.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::time::{Duration, Instant};

use agent::{AnyLearner, ParamSnapshot, PolicyStack};
use proto::{ContentHash, EvalReport, LearnerStep, PriorityUpdate, WeightsSnapshot};
use tokio::sync::mpsc;

use crate::LearnerSettings;
use crate::batch::Sampled;
use crate::checkpoint::CheckpointDir;

/// A progress snapshot for the stats report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Progress {
    /// Updates completed (the learner step).
    pub learner_step: u64,
    /// Updates per second since the previous snapshot.
    pub updates_per_s: f64,
    /// Fraction of that interval spent waiting for a batch.
    pub wait_fraction: f64,
    /// Total time spent waiting for batches, ms.
    pub wait_ms_total: u64,
    /// Mean losses and diagnostics over the interval.
    pub means: LossMeans,
    /// The newest weights version published.
    pub weights_version: u64,
    /// Evaluations skipped because the previous one was still running.
    pub evals_skipped: u64,
    /// Updates with a non-finite loss.
    pub non_finite_updates: u64,
    /// Whether the fused learner runs the updates (else the candle learner).
    pub fused: bool,
}

/// Sums of per-update diagnostics, turned into means.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LossMeans {
    /// Updates summed.
    pub n: u64,
    /// Mean J_Q.
    pub q_loss: f64,
    /// Mean J_V.
    pub v_loss: f64,
    /// Mean policy loss.
    pub policy_loss: f64,
    /// Mean Q(s, a).
    pub mean_q: f64,
    /// Mean log π.
    pub mean_log_prob: f64,
    /// Mean temperature.
    pub temperature: f64,
}

impl LossMeans {
    /// Adds one update's diagnostics to the sums.
    pub fn add(&mut self, m: &agent::Metrics) {
        self.n += 1;
        self.q_loss += f64::from(m.q_loss);
        self.v_loss += f64::from(m.v_loss);
        self.policy_loss += f64::from(m.policy_loss);
        self.mean_q += f64::from(m.mean_q);
        self.mean_log_prob += f64::from(m.mean_log_prob);
        self.temperature += f64::from(m.temperature);
    }

    /// The means of the sums (zeros when nothing was added; `n` says how many were).
    pub fn means(&self) -> LossMeans {
        let n = self.n.max(1) as f64;
        LossMeans {
            n: self.n,
            q_loss: self.q_loss / n,
            v_loss: self.v_loss / n,
            policy_loss: self.policy_loss / n,
            mean_q: self.mean_q / n,
            mean_log_prob: self.mean_log_prob / n,
            temperature: self.temperature / n,
        }
    }
}

/// What the thread sends the shell.
#[derive(Debug)]
pub enum Out {
    /// New priorities for the replay server.
    Priorities(PriorityUpdate),
    /// The learner step, for the param server.
    Step(LearnerStep),
    /// New weights, for the param server.
    Weights(WeightsSnapshot),
    /// An evaluation result.
    Eval(EvalReport),
    /// Progress for the stats report.
    Progress(Box<Progress>),
}

/// What the thread did, when it stops.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UpdaterReport {
    /// The step it started from (a resumed checkpoint's, else 0).
    pub start_step: u64,
    /// The step it stopped at.
    pub final_step: u64,
    /// Weight snapshots published.
    pub weights_published: u64,
    /// Checkpoints written.
    pub checkpoints: u64,
    /// Total time waiting for batches, ms.
    pub wait_ms_total: u64,
    /// Updates with a non-finite loss.
    pub non_finite_updates: u64,
}

/// The update thread's parts.
pub struct Updater {
    /// The learner.
    pub learner: AnyLearner,
    /// The `[learner]` table.
    pub settings: LearnerSettings,
    /// To the shell.
    pub out: mpsc::Sender<Out>,
    /// To the evaluation thread (epoch, weights); `None` without evaluations.
    pub eval: Option<SyncSender<(u64, ParamSnapshot)>>,
    /// Where checkpoints go.
    pub checkpoints: Option<CheckpointDir>,
    /// The learner step, read by the sample requests.
    pub step: Arc<AtomicU64>,
    /// The frozen levels below the trained one (empty for a single level): their content hash is
    /// stamped on every weights frame, and they are embedded in every checkpoint.
    pub frozen: Frozen,
    /// Deterministic mode's schedule, whose checkpoint steps are the only ones resumable.
    pub lockstep: Option<run::Lockstep>,
}

/// Whether `step` is one of the periodic checkpoints (every `checkpoint_every_epochs` epochs).
fn periodic_checkpoint(s: &LearnerSettings, step: u64) -> bool {
    s.checkpoint_every_epochs > 0
        && step.is_multiple_of(s.epoch_length_updates)
        && (step / s.epoch_length_updates).is_multiple_of(s.checkpoint_every_epochs)
}

/// A hierarchy's frozen levels as the update thread uses them.
#[derive(Debug, Default)]
pub struct Frozen {
    /// The levels.
    pub stack: PolicyStack,
    /// Their content hash; `None` without levels.
    pub hash: Option<ContentHash>,
}

impl Frozen {
    /// `stack` and its content hash.
    pub fn new(stack: PolicyStack) -> agent::Result<Self> {
        let hash = if stack.is_empty() { None } else { Some(ContentHash(stack.content_hash()?)) };
        Ok(Self { stack, hash })
    }
}

impl std::fmt::Debug for Updater {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Updater").field("step", &self.learner.step()).finish()
    }
}

impl Updater {
    fn send(&self, message: Out) -> bool {
        // Blocks when the bus is behind: never drop a priority update or a weights version.
        self.out.blocking_send(message).is_ok()
    }

    fn publish_weights(&self, report: &mut UpdaterReport) -> anyhow::Result<u64> {
        let snapshot = self.learner.snapshot()?;
        let version = snapshot.version;
        report.weights_published += 1;
        self.send(Out::Weights(WeightsSnapshot {
            version,
            learner_step: self.learner.step(),
            safetensors: snapshot.safetensors,
            stack: self.frozen.hash,
        }));
        Ok(version)
    }

    fn checkpoint(&self, report: &mut UpdaterReport) {
        let Some(dir) = &self.checkpoints else { return };
        let checkpoint = self.learner.checkpoint().and_then(|c| self.frozen.stack.embed(&c));
        match checkpoint.map_err(anyhow::Error::from).and_then(|c| Ok(dir.write(&c)?)) {
            Ok(path) => {
                report.checkpoints += 1;
                tracing::info!(step = self.learner.step(), path = %path.display(), "checkpoint written");
            }
            Err(error) => tracing::error!(%error, "checkpoint failed"),
        }
    }

    /// Runs updates on `batches` until they end (shutdown) or `max_updates` is reached.
    pub fn run(mut self, mut batches: mpsc::Receiver<Sampled>) -> anyhow::Result<UpdaterReport> {
        let s = self.settings.clone();
        let start_step = self.learner.step();
        let mut report = UpdaterReport { start_step, ..UpdaterReport::default() };
        let mut weights_version = self.publish_weights(&mut report)?;
        self.send(Out::Step(LearnerStep { learner_step: start_step, weights_version, starved: false }));
        let stats_every = Duration::from_millis(s.stats_interval_ms);
        let (mut window_start, mut window_step, mut window_wait) =
            (Instant::now(), start_step, Duration::ZERO);
        let mut total_wait = Duration::ZERO;
        let mut sums = LossMeans::default();
        let mut evals_skipped = 0;
        let mut non_finite_warned = None;
        loop {
            if s.max_updates.is_some_and(|max| self.learner.step() >= max) {
                tracing::info!(step = self.learner.step(), "max_updates reached");
                break;
            }
            let waited = Instant::now();
            let Some(sampled) = batches.blocking_recv() else { break };
            let wait = waited.elapsed();
            window_wait += wait;
            total_wait += wait;
            let out = self.learner.update(&sampled.batch)?;
            let step = self.learner.step();
            self.step.store(step, Ordering::Relaxed);
            if out.metrics.q_loss.is_finite() && out.metrics.v_loss.is_finite() {
                sums.add(&out.metrics);
            } else {
                report.non_finite_updates += 1;
                // A diverging run makes one per update: one line per node::WARN_EVERY, with the count.
                if non_finite_warned.is_none_or(|at: Instant| at.elapsed() >= node::WARN_EVERY) {
                    tracing::warn!(
                        step,
                        q_loss = out.metrics.q_loss,
                        v_loss = out.metrics.v_loss,
                        total = report.non_finite_updates,
                        "non-finite loss"
                    );
                    non_finite_warned = Some(Instant::now());
                }
            }
            let epoch_end = step.is_multiple_of(s.epoch_length_updates);
            let epoch = step / s.epoch_length_updates;
            if periodic_checkpoint(&s, step) {
                // Before this update's priorities: deterministic mode's replay server cuts its state
                // at a checkpoint step once they arrive, so no cut exists without its checkpoint.
                self.checkpoint(&mut report);
            }
            if s.send_priorities {
                let td_errors = out.td_errors.iter().map(|d| d.abs()).collect();
                let update = PriorityUpdate {
                    learner_step: step,
                    slots: sampled.slots,
                    generations: sampled.generations,
                    td_errors,
                };
                if !self.send(Out::Priorities(update)) {
                    break;
                }
            }
            if step.is_multiple_of(s.publish_weights_every_updates) {
                weights_version = self.publish_weights(&mut report)?;
            }
            if step.is_multiple_of(s.announce_every_updates) {
                self.send(Out::Step(LearnerStep { learner_step: step, weights_version, starved: false }));
            }
            if epoch_end
                && let Some(eval) = self.eval.as_ref().filter(|_| epoch.is_multiple_of(s.eval_every_epochs))
            {
                match eval.try_send((epoch, self.learner.snapshot()?)) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_)) => evals_skipped += 1,
                    Err(TrySendError::Disconnected(_)) => self.eval = None,
                }
            }
            if window_start.elapsed() >= stats_every {
                let seconds = window_start.elapsed().as_secs_f64();
                let progress = Progress {
                    learner_step: step,
                    updates_per_s: (step - window_step) as f64 / seconds,
                    wait_fraction: window_wait.as_secs_f64() / seconds,
                    wait_ms_total: total_wait.as_millis() as u64,
                    means: sums.means(),
                    weights_version,
                    evals_skipped,
                    non_finite_updates: report.non_finite_updates,
                    fused: self.learner.backend() == agent::Backend::Fused,
                };
                self.send(Out::Progress(Box::new(progress)));
                (window_start, window_step, window_wait) = (Instant::now(), step, Duration::ZERO);
                sums = LossMeans::default();
            }
        }
        let step = self.learner.step();
        if step > start_step {
            weights_version = self.publish_weights(&mut report)?;
            self.send(Out::Step(LearnerStep { learner_step: step, weights_version, starved: false }));
            // A periodic checkpoint step was written with its update. Deterministic mode resumes
            // only at the schedule's cuts, which the periodic checkpoints are; one at another step
            // could not be continued exactly.
            match (periodic_checkpoint(&s, step), self.lockstep) {
                (true, _) => {}
                (false, None) => self.checkpoint(&mut report),
                (false, Some(_)) => tracing::info!(
                    step,
                    "deterministic mode: no checkpoint at shutdown (not a checkpoint step)"
                ),
            }
        }
        report.final_step = step;
        report.wait_ms_total = total_wait.as_millis() as u64;
        Ok(report)
    }
}
