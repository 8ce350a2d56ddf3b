//! Deterministic mode's replay side, sans-IO (`run::lockstep` has the schedule): experience is
//! staged per (block, executor) as it arrives and enters the buffer only when a round's first
//! sample needs it, in the canonical order; priority updates are queued and applied only up to the
//! step of the previous sample request. So what a sample sees depends on the schedule alone, never
//! on which message arrived first.
//!
//! At each checkpoint step `c` of the learner (a round's start) the state is cut: once every
//! executor has delivered its blocks through `c / R` and the learner's priority updates through `c`
//! are in, and before the sample at `c` is served, the service snapshots the buffer with this
//! state ([`Saved`]). A run resumed from the learner's checkpoint at `c` and this snapshot
//! continues exactly as the uninterrupted run (README "Deterministic mode").

use std::collections::BTreeMap;

use proto::{ExperienceBatch, PriorityUpdate, SampledBatch};
use serde::{Deserialize, Serialize};

/// What a sample request still waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockstepWait {
    /// An executor has not delivered the steps the round samples from.
    Experience {
        /// The executor.
        executor: u32,
        /// Env steps it delivered.
        have: u64,
        /// Env steps the round needs.
        need: u64,
    },
    /// A priority update the sample must see has not arrived.
    Priorities {
        /// Its learner step.
        missing: u64,
    },
    /// The sample at a checkpoint step waits for the cut (the snapshot of the state before it).
    Cut {
        /// The checkpoint step.
        at: u64,
    },
}

impl std::fmt::Display for LockstepWait {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LockstepWait::Experience { executor, have, need } => {
                write!(
                    f,
                    "deterministic mode: executor {executor} delivered {have} of the {need} env steps this round samples"
                )
            }
            LockstepWait::Priorities { missing } => {
                write!(f, "deterministic mode: waiting for the priority update of learner step {missing}")
            }
            LockstepWait::Cut { at } => {
                write!(f, "deterministic mode: the state at checkpoint step {at} is not saved yet")
            }
        }
    }
}

/// What to do for a sample request that may go ahead.
#[derive(Debug, PartialEq)]
pub enum Plan {
    /// Apply the queued priorities through `priorities_through`, insert the staged blocks through
    /// `blocks_through`, then sample.
    Sample {
        /// Last learner step whose priority update is applied first.
        priorities_through: u64,
        /// Last block inserted first.
        blocks_through: u64,
    },
    /// The request for the step just served, asked again (its reply was lost or late): the same batch.
    Repeat(SampledBatch),
    /// A request for a step before the one last served: it cannot be answered the same way again.
    Stale {
        /// The step last served.
        served: u64,
    },
}

/// The staging state.
#[derive(Debug, Clone)]
pub struct Lockstep {
    schedule: run::Lockstep,
    /// Env steps each executor has delivered (its batches arrive in order).
    progress: Vec<u64>,
    /// Batches not yet in the buffer, by (block, executor), each executor's in arrival order.
    staged: BTreeMap<(u64, u32), Vec<ExperienceBatch>>,
    /// Blocks below this are in the buffer.
    inserted_blocks: u64,
    /// Priority updates not yet applied, by learner step.
    queued: BTreeMap<u64, PriorityUpdate>,
    /// Updates through this learner step are applied.
    applied_through: u64,
    /// The step of the last request served, and its batch (`None` after a restore).
    last: Option<(u64, Option<SampledBatch>)>,
    /// The last checkpoint step cut (0: none yet); `None` when cuts are off (no snapshots).
    cut: Option<u64>,
}

/// Deterministic mode's state at a cut, saved beside the buffer in the snapshot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Saved {
    /// The learner step of the cut.
    pub cut: u64,
    /// Env steps each executor had delivered through the cut's block.
    pub progress: Vec<u64>,
    /// The staged batches of the cut's block (and any before it not yet inserted).
    pub staged: BTreeMap<(u64, u32), Vec<ExperienceBatch>>,
    /// Blocks below this were in the buffer.
    pub inserted_blocks: u64,
    /// Priority updates queued, through the cut's step.
    pub queued: Vec<PriorityUpdate>,
    /// Updates through this step were applied.
    pub applied_through: u64,
    /// The step of the last request served.
    pub served: Option<u64>,
}

impl Lockstep {
    /// Nothing staged, nothing served.
    pub fn new(schedule: run::Lockstep) -> Self {
        Self {
            schedule,
            progress: vec![0; schedule.executors as usize],
            staged: BTreeMap::new(),
            inserted_blocks: 0,
            queued: BTreeMap::new(),
            applied_through: 0,
            last: None,
            cut: None,
        }
    }

    /// Cuts the state at every checkpoint step (snapshots are on).
    pub fn with_cuts(mut self) -> Self {
        self.cut = Some(self.cut.unwrap_or(0));
        self
    }

    /// Picks up where a cut left off.
    pub fn restore(schedule: run::Lockstep, saved: Saved) -> Self {
        let mut restored = Self::new(schedule).with_cuts();
        restored.progress = saved.progress;
        restored.progress.resize(schedule.executors as usize, 0);
        restored.staged = saved.staged;
        restored.inserted_blocks = saved.inserted_blocks;
        restored.queued = saved.queued.into_iter().map(|u| (u.learner_step, u)).collect();
        restored.applied_through = saved.applied_through;
        restored.last = saved.served.map(|step| (step, None));
        restored.cut = Some(saved.cut);
        restored
    }

    /// The last checkpoint step cut or restored (0 before any).
    pub fn last_cut(&self) -> u64 {
        self.cut.unwrap_or(0)
    }

    /// Whether it cuts the state at checkpoint steps (only with snapshots: what a run resumes from).
    pub fn cuts(&self) -> bool {
        self.cut.is_some()
    }

    /// Env steps executor `id` has delivered.
    pub fn progress(&self) -> &[u64] {
        &self.progress
    }

    /// The next checkpoint step to cut at, if cuts are on and it is due now: every block it needs
    /// and every priority update through it are in, and its sample is not served yet.
    pub fn cut_due(&self) -> Option<u64> {
        let at = self.cut? + self.schedule.checkpoint_every_updates;
        let need = self.schedule.needed_for(at);
        let served = self.last.as_ref().map(|(step, _)| *step);
        let ready = self.progress.iter().all(|have| *have >= need)
            && (self.applied_through + 1..=at).all(|s| self.queued.contains_key(&s))
            && served.is_none_or(|s| s < at);
        ready.then_some(at)
    }

    /// The state at checkpoint step `at` (from [`Lockstep::cut_due`]), recorded as cut.
    pub fn cut(&mut self, at: u64) -> Saved {
        self.cut = Some(at);
        let (block, end) = (self.schedule.round(at), self.schedule.needed_for(at));
        Saved {
            cut: at,
            progress: self.progress.iter().map(|have| (*have).min(end)).collect(),
            staged: self.staged.range(..(block + 1, 0)).map(|(k, v)| (*k, v.clone())).collect(),
            inserted_blocks: self.inserted_blocks,
            queued: self.queued.range(..=at).map(|(_, u)| u.clone()).collect(),
            applied_through: self.applied_through,
            served: self.last.as_ref().map(|(step, _)| *step),
        }
    }

    /// Stages a checked batch; the error is a rejection's reason and detail.
    pub fn stage(&mut self, batch: ExperienceBatch) -> Result<(), (&'static str, String)> {
        let (executor, env_steps) = (batch.executor_id, batch.env_steps);
        let Some(have) = self.progress.get_mut(executor as usize) else {
            let n = self.schedule.executors;
            return Err(("lockstep_executor", format!("executor {executor}: this run has executors 0..{n}")));
        };
        if env_steps == 0 || env_steps < *have {
            let detail = format!("executor {executor}: a batch ending at env step {env_steps} after {have}");
            return Err(("lockstep_order", detail));
        }
        let block = self.schedule.block_of(env_steps - 1);
        if block < self.inserted_blocks {
            let detail = format!("executor {executor}: block {block} is already in the buffer");
            return Err(("lockstep_order", detail));
        }
        *have = env_steps;
        if !batch.is_empty() {
            self.staged.entry((block, executor)).or_default().push(batch);
        }
        Ok(())
    }

    /// Queues a priority update; false for one already applied (a repeat).
    pub fn queue(&mut self, update: PriorityUpdate) -> bool {
        if update.learner_step <= self.applied_through {
            return false;
        }
        self.queued.insert(update.learner_step, update);
        true
    }

    /// What the sample at `learner_step` may do now, or what it waits for.
    pub fn plan(&self, learner_step: u64) -> Result<Plan, LockstepWait> {
        let previous = match &self.last {
            Some((served, Some(batch))) if *served == learner_step => return Ok(Plan::Repeat(batch.clone())),
            Some((served, _)) if *served >= learner_step => return Ok(Plan::Stale { served: *served }),
            Some((served, _)) => *served,
            None => self.applied_through,
        };
        if let Some(cut) = self.cut
            && learner_step >= cut + self.schedule.checkpoint_every_updates
        {
            return Err(LockstepWait::Cut { at: cut + self.schedule.checkpoint_every_updates });
        }
        let need = self.schedule.needed_for(learner_step);
        if let Some((executor, &have)) = self.progress.iter().enumerate().find(|(_, have)| **have < need) {
            return Err(LockstepWait::Experience { executor: executor as u32, have, need });
        }
        if let Some(missing) = (self.applied_through + 1..=previous).find(|s| !self.queued.contains_key(s)) {
            return Err(LockstepWait::Priorities { missing });
        }
        Ok(Plan::Sample { priorities_through: previous, blocks_through: self.schedule.round(learner_step) })
    }

    /// The queued updates through `step`, in order, taken out.
    pub fn take_priorities(&mut self, step: u64) -> Vec<PriorityUpdate> {
        let later = self.queued.split_off(&(step + 1));
        self.applied_through = self.applied_through.max(step);
        std::mem::replace(&mut self.queued, later).into_values().collect()
    }

    /// The staged batches of blocks through `block`, in the canonical order, taken out.
    pub fn take_blocks(&mut self, block: u64) -> Vec<ExperienceBatch> {
        let later = self.staged.split_off(&(block + 1, 0));
        self.inserted_blocks = self.inserted_blocks.max(block + 1);
        std::mem::replace(&mut self.staged, later).into_values().flatten().collect()
    }

    /// Records the batch served for `learner_step`, for a repeat of the request.
    pub fn served(&mut self, learner_step: u64, batch: &SampledBatch) {
        self.last = Some((learner_step, Some(batch.clone())));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule() -> run::Lockstep {
        run::Lockstep::new(run::LockstepKeys {
            executors: 2,
            warm_up_transitions: 8,
            updates_per_round: 10,
            env_steps_per_round: 3,
        })
        .unwrap()
    }

    fn batch(executor: u32, env_steps: u64, n: usize) -> ExperienceBatch {
        let mut transitions = proto::Transitions::with_capacity(1, 1, n);
        for i in 0..n {
            let x = [env_steps as f32 + i as f32];
            let row = proto::Transition {
                observation: &x,
                action: &x,
                reward: 0.0,
                next_observation: &x,
                terminated: false,
            };
            transitions.push(row).unwrap();
        }
        let td_errors = vec![1.0; n];
        ExperienceBatch {
            executor_id: executor,
            stream: 0,
            seq: 0,
            weights_version: 0,
            env_steps,
            transitions,
            td_errors,
        }
    }

    fn update(learner_step: u64) -> PriorityUpdate {
        PriorityUpdate { learner_step, slots: vec![], generations: vec![], td_errors: vec![] }
    }

    #[test]
    fn a_round_waits_for_every_executors_block_and_inserts_in_canonical_order() {
        let mut l = Lockstep::new(schedule());
        // Warm-up: 4 steps each. Executor 1's arrive first, then part of executor 0's.
        l.stage(batch(1, 4, 2)).unwrap();
        l.stage(batch(0, 2, 1)).unwrap();
        assert_eq!(l.plan(0), Err(LockstepWait::Experience { executor: 0, have: 2, need: 4 }));
        // A marker completes executor 0's block 0; executor 1 is already into block 1.
        l.stage(batch(1, 6, 1)).unwrap();
        l.stage(batch(0, 4, 0)).unwrap();
        assert_eq!(l.plan(0), Ok(Plan::Sample { priorities_through: 0, blocks_through: 0 }));
        let order: Vec<(u32, u64)> = l.take_blocks(0).iter().map(|b| (b.executor_id, b.env_steps)).collect();
        assert_eq!(order, vec![(0, 2), (1, 4)], "executor 0 first, block 1 still staged");
        // Late and foreign batches are refused.
        assert_eq!(l.stage(batch(0, 3, 1)).unwrap_err().0, "lockstep_order");
        assert_eq!(l.stage(batch(2, 3, 1)).unwrap_err().0, "lockstep_executor");
    }

    #[test]
    fn the_state_is_cut_at_a_checkpoint_before_its_sample_and_restored_from_the_cut() {
        let schedule = run::Lockstep { checkpoint_every_updates: 20, ..schedule() };
        let mut l = Lockstep::new(schedule).with_cuts();
        // Blocks 0..=2 end at env step 10; executor 1 is already into block 3.
        l.stage(batch(0, 10, 2)).unwrap();
        l.stage(batch(1, 10, 2)).unwrap();
        l.stage(batch(1, 12, 1)).unwrap();
        for step in 1..=19 {
            l.queue(update(step));
        }
        l.last = Some((16, None));
        assert_eq!(l.cut_due(), None, "the priority update of step 20 is missing");
        assert_eq!(l.plan(20), Err(LockstepWait::Cut { at: 20 }), "no sample at 20 before the cut");
        l.queue(update(20));
        assert_eq!(l.cut_due(), Some(20));
        let saved = l.cut(20);
        assert_eq!((saved.cut, saved.progress.clone(), saved.served), (20, vec![10, 10], Some(16)));
        assert_eq!(
            saved.staged.keys().copied().collect::<Vec<_>>(),
            vec![(2, 0), (2, 1)],
            "block 3 is not saved"
        );
        assert_eq!(saved.queued.len(), 20);
        assert_eq!(l.cut_due(), None, "the next cut is at 40");
        // Restored, the sample at 20 sees what it would have seen.
        let restored = Lockstep::restore(schedule, saved);
        assert_eq!(restored.last_cut(), 20);
        assert_eq!(restored.plan(20), l.plan(20));
        assert_eq!(restored.plan(20), Ok(Plan::Sample { priorities_through: 16, blocks_through: 2 }));
    }

    #[test]
    fn a_sample_sees_the_priorities_through_the_previous_request_only() {
        let mut l = Lockstep::new(schedule());
        l.stage(batch(0, 4, 1)).unwrap();
        l.stage(batch(1, 4, 1)).unwrap();
        l.take_blocks(0);
        let served = SampledBatch {
            request_id: 1,
            learner_step: 0,
            slots: vec![],
            generations: vec![],
            is_weights: vec![],
            transitions: proto::Transitions::with_capacity(1, 1, 0),
        };
        l.served(0, &served);
        assert!(matches!(l.plan(0), Ok(Plan::Repeat(_))));
        // Request at 4 (4 batches per request): needs the updates of steps 1..=0, i.e. none.
        l.served(4, &served);
        // Request at 8 needs updates 1..=4; 3 is missing, later ones may already be here.
        for step in [1, 2, 4, 5, 6] {
            assert!(l.queue(update(step)));
        }
        assert_eq!(l.plan(8), Err(LockstepWait::Priorities { missing: 3 }));
        l.queue(update(3));
        assert_eq!(l.plan(8), Ok(Plan::Sample { priorities_through: 4, blocks_through: 0 }));
        let applied: Vec<u64> = l.take_priorities(4).iter().map(|u| u.learner_step).collect();
        assert_eq!(applied, vec![1, 2, 3, 4]);
        assert!(!l.queue(update(2)), "an applied step is a repeat");
        assert_eq!(l.plan(2), Ok(Plan::Stale { served: 4 }));
        // Round 1 (step 10) needs block 1 (7 steps each).
        l.served(8, &served);
        assert_eq!(l.plan(10), Err(LockstepWait::Experience { executor: 0, have: 4, need: 7 }));
    }
}
