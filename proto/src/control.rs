//! Control: the global step that paces everything, and each executor's view of the barrier.
//!
//! The barrier keeps executors at most `max_env_steps_ahead` environment steps ahead of what the
//! learner has consumed, keyed by the global (learner) step; executors block when they reach it and
//! say so in their [`BarrierReport`], so a stall is visible instead of silent.

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// Announcement on `control/step` (learner or param server → all): where the learner is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GlobalStep {
    /// Gradient steps the learner has completed.
    pub learner_step: u64,
    /// Version of the newest weights published (a learner step, ≤ `learner_step`).
    pub weights_version: u64,
    /// The barrier's k: the most environment steps an executor may take beyond what `learner_step`
    /// permits (the executor's barrier owns the exact rule). Positive, or every executor would block forever.
    pub max_env_steps_ahead: u64,
}

impl Sealed for GlobalStep {}

impl Message for GlobalStep {
    const KIND: MessageKind = MessageKind::GlobalStep;

    fn validate(&self) -> Result<(), ValidationError> {
        check::positive("max_env_steps_ahead", self.max_env_steps_ahead)
    }
}

/// One executor's barrier state on `control/barrier/<executor_id>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BarrierReport {
    /// The reporting executor.
    pub executor_id: u32,
    /// Its cumulative environment steps.
    pub env_steps: u64,
    /// The newest [`GlobalStep::learner_step`] it has seen.
    pub learner_step_seen: u64,
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
