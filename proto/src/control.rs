//! Control: the global step that paces everything, the learner's progress behind it, and each
//! executor's view of the barrier.
//!
//! The barrier rule is part of the contract, so it lives here and every role computes it the same way
//! ([`GlobalStep::allowance`]): an executor that joined when the learner was at step `s0` may have
//! taken at most `warm_up_share + k × (learner_step − s0)` env steps. The param server owns the
//! inputs (the learner's step, the live executors, the weight versions) and announces them; executors
//! block when they reach the allowance and say so in their [`BarrierReport`], so a stall is visible
//! instead of silent.

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// Announcement on `control/step` (param server → all): where the learner is, and the barrier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GlobalStep {
    /// Gradient steps the learner has completed (never decreases within one param-server run).
    pub learner_step: u64,
    /// Version of the newest weights the param server holds (a learner step, ≤ `learner_step`).
    pub weights_version: u64,
    /// k: env steps each executor may take per learner step (the dissertation: 1). Positive, or every
    /// executor would block forever.
    pub env_steps_per_learner_step: u64,
    /// Env steps each executor may take before the learner's first step: the replay minimum shared
    /// between the live executors, so the dead never hold the rest back (plus any refill granted
    /// to a starved learner, see [`LearnerStep::starved`]).
    pub warm_up_share: u64,
    /// Executors must act with weights of at least this version (0: no lag bound).
    pub min_weights_version: u64,
    /// Executors the param server sees alive.
    pub live_executors: u32,
}

impl GlobalStep {
    /// Cumulative env steps an executor that joined at learner step `joined_at` may have taken.
    pub fn allowance(&self, joined_at: u64) -> u64 {
        let steps = self.learner_step.saturating_sub(joined_at);
        self.warm_up_share.saturating_add(self.env_steps_per_learner_step.saturating_mul(steps))
    }
}

impl Sealed for GlobalStep {}

impl Message for GlobalStep {
    const KIND: MessageKind = MessageKind::GlobalStep;

    fn validate(&self) -> Result<(), ValidationError> {
        check::positive("env_steps_per_learner_step", self.env_steps_per_learner_step)
    }
}

/// The learner's progress on `control/learner` (learner → param server), a few times per second to
/// every few updates: the input of the global step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LearnerStep {
    /// Gradient steps completed.
    pub learner_step: u64,
    /// Version of the newest weights the learner has published.
    pub weights_version: u64,
    /// The learner has waited a second or more for data: the replay server refuses for lack of it
    /// (below its minimum, or held to its samples-per-insert ratio); a silent replay server is not
    /// starvation. Repeated every 250 ms while it lasts, then once `false`. With every executor at
    /// the barrier this is a deadlock (a replay server restarted empty); the param server breaks it
    /// by granting a fresh warm-up share.
    pub starved: bool,
}

impl Sealed for LearnerStep {}

impl Message for LearnerStep {
    const KIND: MessageKind = MessageKind::LearnerStep;

    /// Every combination of values is meaningful.
    fn validate(&self) -> Result<(), ValidationError> {
        Ok(())
    }
}

/// One executor's barrier state on `control/barrier/<executor_id>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BarrierReport {
    /// The reporting executor.
    pub executor_id: u32,
    /// Its cumulative environment steps.
    pub env_steps: u64,
    /// Its allowance at the newest global step it has seen ([`GlobalStep::allowance`]).
    pub allowed_env_steps: u64,
    /// The newest [`GlobalStep::learner_step`] it has seen.
    pub learner_step_seen: u64,
    /// The learner step at which it joined (its barrier's origin).
    pub joined_at: u64,
    /// Version of the weights it acts with.
    pub weights_version: u64,
    /// Whether it is waiting at the barrier right now.
    pub blocked: bool,
    /// Total milliseconds spent blocked since it started.
    pub blocked_ms_total: u64,
}

impl Sealed for BarrierReport {}

impl Message for BarrierReport {
    const KIND: MessageKind = MessageKind::BarrierReport;

    /// Every combination of values is meaningful; the type says it all.
    fn validate(&self) -> Result<(), ValidationError> {
        Ok(())
    }
}

/// How an evaluation picks the policy's latent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EvalMode {
    /// The paper's: one h ~ N(0, I) drawn per evaluation and held for all its episodes.
    #[default]
    FixedLatent,
    /// h = 0 for every step: the counterpart of a Gaussian policy's mean action.
    ZeroLatent,
    /// A fresh z ~ N(0, I) every step: the policy that collects the data.
    Stochastic,
}

impl EvalMode {
    /// The run-file spelling.
    pub fn name(self) -> &'static str {
        match self {
            Self::FixedLatent => "fixed_latent",
            Self::ZeroLatent => "zero_latent",
            Self::Stochastic => "stochastic",
        }
    }
}

/// A learner evaluation on `eval`: N episodes after an epoch, in one [`EvalMode`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// The epoch just finished (learner steps / epoch length).
    pub epoch: u64,
    /// The learner step of the evaluated weights.
    pub learner_step: u64,
    /// Episodes averaged; positive.
    pub episodes: u32,
    /// Mean undiscounted return; finite.
    pub mean_return: f64,
    /// Mean episode length.
    pub mean_length: f64,
    /// Standard deviation of the episodes' returns (0 for one episode); finite.
    pub std_return: f64,
    /// How the latent was chosen.
    pub mode: EvalMode,
    /// With HER: the fraction of episodes that reached their goal at some step; in [0, 1].
    pub goal_success: Option<f64>,
}

impl Sealed for EvalReport {}

impl Message for EvalReport {
    const KIND: MessageKind = MessageKind::EvalReport;

    fn validate(&self) -> Result<(), ValidationError> {
        check::positive("episodes", u64::from(self.episodes))?;
        check::finite_f64("mean_return", self.mean_return)?;
        check::finite_f64("std_return", self.std_return)?;
        check::finite_f64("mean_length", self.mean_length)?;
        check::fraction("goal_success", self.goal_success)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allowance_is_the_share_plus_k_per_learner_step_since_joining() {
        let step = GlobalStep {
            learner_step: 100,
            weights_version: 100,
            env_steps_per_learner_step: 2,
            warm_up_share: 50,
            min_weights_version: 0,
            live_executors: 4,
        };
        assert_eq!(step.allowance(0), 250);
        assert_eq!(step.allowance(60), 130);
        // Joined "after" the announced step (a learner restarted from an older checkpoint): the share only.
        assert_eq!(step.allowance(500), 50);
        let huge = GlobalStep { learner_step: u64::MAX, env_steps_per_learner_step: u64::MAX, ..step };
        assert_eq!(huge.allowance(0), u64::MAX);
    }
}
