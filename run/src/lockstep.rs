//! Deterministic mode's schedule, shared by every role: which executor env steps each learner
//! update may see, and which weights version each env step must act with. With it, N executors and
//! the same run file give bit-identical learner parameters whatever the timing (README
//! "Deterministic mode").
//!
//! Time is cut into rounds of `R` learner updates. Each executor's env steps are cut into blocks:
//! block 0 is its warm-up share (`W` steps), block `j ≥ 1` the next `T` steps. Then:
//!
//! - round `j`'s updates sample from exactly blocks `0..=j` of every executor, inserted in the
//!   canonical order (block, then executor id, then the executor's own order);
//! - block `j + 1` is stepped with the weights of version `j·R` (blocks 0 and 1 with version 0), the
//!   learner's weights at the start of round `j`, so executors step the next block while the
//!   learner trains on this one;
//! - an executor may step block `j + 1` once the learner has reached step `j·R`: the barrier.
//!
//! The learner waits at a round's start for the round's blocks, the executors wait at a block's end
//! for the learner; how long either waits changes nothing but the time taken.
//!
//! Checkpoints: the learner's checkpoint steps (`[learner] epoch_length_updates ×
//! checkpoint_every_epochs`, `E`) must be round starts. At each, every role's state is cut so that a
//! resumed run continues exactly: the learner's checkpoint, the replay server's snapshot, and the
//! executors' state, which is made trivial: at the end of a checkpoint's block each executor ends
//! its episode (a truncation, as a time limit) and restarts its streams from a seed of the
//! checkpoint step, so a resumed executor only needs the step ([`Lockstep::cut_seed`]).

use crate::overrides::EXECUTORS_ENV;
use serde::Deserialize;

/// The `[lockstep]` table: deterministic mode's schedule (read only when `[train] deterministic`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LockstepKeys {
    /// N: the executors of the run, ids `0..N`; every one of them must deliver each block. No
    /// default: the run file or the launcher (`SACLSP_EXECUTORS`, which wins) names it.
    pub executors: u32,
    /// Transitions all executors collect together before the learner's first update; each steps
    /// `ceil(warm_up_transitions / N)` of them (block 0). Default 10 000, as `[param_server]`'s.
    pub warm_up_transitions: u64,
    /// R: learner updates per round; the learner publishes its weights once per round. Default 500,
    /// the default run's `publish_weights_every_updates`.
    pub updates_per_round: u64,
    /// T: env steps each executor takes per round. Default 200: with 8 executors, 3.2 env steps per
    /// update, about what the default run's normal mode settles at on two cores.
    pub env_steps_per_round: u64,
}

impl Default for LockstepKeys {
    fn default() -> Self {
        Self { executors: 0, warm_up_transitions: 10_000, updates_per_round: 500, env_steps_per_round: 200 }
    }
}

/// The schedule, validated: the quantities of the module doc.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lockstep {
    /// N.
    pub executors: u32,
    /// W: each executor's warm-up steps (block 0).
    pub warm_up_steps: u64,
    /// R.
    pub updates_per_round: u64,
    /// T.
    pub env_steps_per_round: u64,
    /// E: the learner's checkpoint period in updates, a multiple of R (0: checkpoints only at
    /// shutdown, and no cuts).
    pub checkpoint_every_updates: u64,
}

impl Lockstep {
    /// The schedule of a run file: `None` unless `[train] deterministic = true` (or
    /// `SACLSP_DETERMINISTIC=1`); then `[lockstep]`, with `SACLSP_EXECUTORS` over its `executors`,
    /// and the learner's checkpoint period from `[learner]`.
    pub(crate) fn from_document(
        document: &toml::Table,
        deterministic: bool,
        executors: Option<u32>,
    ) -> Result<Option<Lockstep>, String> {
        /// The learner's checkpoint period, as its `[learner]` table gives it (same defaults).
        #[derive(Deserialize)]
        #[serde(default)]
        struct Checkpoints {
            epoch_length_updates: u64,
            checkpoint_every_epochs: u64,
        }
        impl Default for Checkpoints {
            fn default() -> Self {
                Self { epoch_length_updates: 1000, checkpoint_every_epochs: 100 }
            }
        }
        if !deterministic {
            return Ok(None);
        }
        let mut keys: LockstepKeys = crate::table::table(document, "lockstep")?;
        if let Some(n) = executors {
            keys.executors = n;
        }
        let c: Checkpoints = crate::table::table(document, "learner")?;
        let mut schedule = Self::new(keys)?;
        schedule.checkpoint_every_updates = c.epoch_length_updates.saturating_mul(c.checkpoint_every_epochs);
        if !schedule.checkpoint_every_updates.is_multiple_of(schedule.updates_per_round) {
            return Err(format!(
                "deterministic mode checkpoints at round starts: [learner] epoch_length_updates × \
                 checkpoint_every_epochs ({}) must be a multiple of [lockstep] updates_per_round ({})",
                schedule.checkpoint_every_updates, schedule.updates_per_round
            ));
        }
        Ok(Some(schedule))
    }

    /// The schedule of `keys`, without checkpoints; the error names the key.
    pub fn new(keys: LockstepKeys) -> Result<Lockstep, String> {
        let positive = [
            ("executors", u64::from(keys.executors)),
            ("warm_up_transitions", keys.warm_up_transitions),
            ("updates_per_round", keys.updates_per_round),
            ("env_steps_per_round", keys.env_steps_per_round),
        ];
        if let Some(key) = crate::table::first_zero(&positive) {
            return Err(format!(
                "[lockstep] {key} must be > 0 in deterministic mode (executors: or {EXECUTORS_ENV})"
            ));
        }
        Ok(Lockstep {
            executors: keys.executors,
            warm_up_steps: keys.warm_up_transitions.div_ceil(u64::from(keys.executors)),
            updates_per_round: keys.updates_per_round,
            env_steps_per_round: keys.env_steps_per_round,
            checkpoint_every_updates: 0,
        })
    }

    /// Whether the learner step `step` is a checkpoint step (where the state is cut).
    pub fn is_cut(&self, learner_step: u64) -> bool {
        self.checkpoint_every_updates > 0
            && learner_step > 0
            && learner_step.is_multiple_of(self.checkpoint_every_updates)
    }

    /// The checkpoint step whose block ends at env step `env_steps`, if that block's end is a cut.
    pub fn cut_ending_at(&self, env_steps: u64) -> Option<u64> {
        let block = self.block_of(env_steps.checked_sub(1)?);
        let at = block * self.updates_per_round;
        (self.block_end(block) == env_steps && self.is_cut(at)).then_some(at)
    }

    /// The seed executor `id`'s streams restart from at checkpoint step `at`.
    pub fn cut_seed(seed: u64, id: u32, at: u64) -> u64 {
        // splitmix64's increment spreads consecutive checkpoints apart before the executor's mix.
        crate::seed::mix_seed(seed ^ at.wrapping_mul(crate::seed::GOLDEN), id)
    }

    /// The round learner step `step` is in.
    pub fn round(&self, learner_step: u64) -> u64 {
        learner_step / self.updates_per_round
    }

    /// Each executor's env steps in blocks `0..=block`: where block `block` ends.
    pub fn block_end(&self, block: u64) -> u64 {
        self.warm_up_steps + self.env_steps_per_round * block
    }

    /// The block env step `step` (0-based) belongs to.
    pub fn block_of(&self, env_step: u64) -> u64 {
        match env_step.checked_sub(self.warm_up_steps) {
            None => 0,
            Some(past) => past / self.env_steps_per_round + 1,
        }
    }

    /// The weights version env step `step` must act with.
    pub fn weights_for(&self, env_step: u64) -> u64 {
        self.updates_per_round * self.block_of(env_step).saturating_sub(1)
    }

    /// Env steps each executor may have taken when the learner is at `learner_step`.
    pub fn allowance(&self, learner_step: u64) -> u64 {
        self.block_end(self.round(learner_step) + 1)
    }

    /// Env steps every executor must have delivered before the update at `learner_step` samples.
    pub fn needed_for(&self, learner_step: u64) -> u64 {
        self.block_end(self.round(learner_step))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule() -> Lockstep {
        let keys = LockstepKeys {
            executors: 4,
            warm_up_transitions: 30,
            updates_per_round: 10,
            env_steps_per_round: 5,
        };
        Lockstep::new(keys).unwrap()
    }

    #[test]
    fn blocks_rounds_weights_and_the_barrier_agree() {
        let s = schedule();
        assert_eq!(s.warm_up_steps, 8, "ceil(30 / 4)");
        // Block 0 is the warm-up, then blocks of 5.
        assert_eq!([0, 7, 8, 12, 13].map(|e| s.block_of(e)), [0, 0, 1, 1, 2]);
        assert_eq!((s.block_end(0), s.block_end(1), s.block_end(2)), (8, 13, 18));
        // Blocks 0 and 1 act with version 0, block j+1 with version j·R.
        assert_eq!([0, 12, 13, 17, 18].map(|e| s.weights_for(e)), [0, 0, 10, 10, 20]);
        // Round 0 (steps 0..10) samples block 0 while block 1 is stepped; round 1 needs block 1.
        assert_eq!((s.needed_for(0), s.needed_for(9), s.needed_for(10)), (8, 8, 13));
        assert_eq!((s.allowance(0), s.allowance(9), s.allowance(10)), (13, 13, 18));
        // Every step allowed at learner step L acts with a version the learner has published by L.
        for learner_step in 0..100 {
            for env_step in 0..s.allowance(learner_step) {
                assert!(s.weights_for(env_step) <= learner_step, "{env_step} at {learner_step}");
            }
            // And the round's data is within what executors may step by then: no deadlock.
            assert!(s.needed_for(learner_step) <= s.allowance(learner_step));
        }
    }

    #[test]
    fn cuts_are_at_checkpoint_steps_and_end_their_blocks() {
        let s = Lockstep { checkpoint_every_updates: 20, ..schedule() };
        assert!(!s.is_cut(0) && !s.is_cut(10) && s.is_cut(20) && s.is_cut(40));
        // Block 2 (steps 13..18) is the one stepped with version 10·... and sampled from step 20.
        assert_eq!(s.cut_ending_at(18), Some(20));
        assert_eq!((s.cut_ending_at(13), s.cut_ending_at(17), s.cut_ending_at(0)), (None, None, None));
        assert_eq!(s.cut_ending_at(s.block_end(4)), Some(40));
        assert_ne!(Lockstep::cut_seed(1, 0, 20), Lockstep::cut_seed(1, 0, 40));
        assert_ne!(Lockstep::cut_seed(1, 0, 20), Lockstep::cut_seed(1, 1, 20));
    }

    #[test]
    fn off_unless_asked_and_zeros_are_named() {
        let from_run_file = |text: &str| {
            crate::RunSpec::parse_with(text, &crate::Overrides::default()).map(|spec| spec.lockstep)
        };
        assert_eq!(from_run_file("[train]\nseed = 1\n"), Ok(None));
        let err = from_run_file("[train]\ndeterministic = true\n").unwrap_err();
        assert!(err.contains("executors"), "{err}");
        let on = "[train]\ndeterministic = true\n[lockstep]\nexecutors = 2\nupdates_per_round = 25\n";
        let s = from_run_file(on).unwrap().unwrap();
        assert_eq!((s.executors, s.warm_up_steps, s.updates_per_round), (2, 5000, 25));
        assert_eq!(s.checkpoint_every_updates, 100_000, "the learner's defaults: 100 epochs of 1000");
        let odd = format!("{on}[learner]\nepoch_length_updates = 110\ncheckpoint_every_epochs = 1\n");
        assert!(from_run_file(&odd).unwrap_err().contains("multiple of [lockstep] updates_per_round"));
        assert!(from_run_file("[train]\ndeterministic = true\n[lockstep]\nexecutor = 2\n").is_err());
    }
}
