//! The global-step barrier, sans-IO: what the param server announces on `control/step`, from the
//! learner's step, the live executors and the published weight versions.
//!
//! Rule (the dissertation's "one executor step per learner step", made exact and per executor;
//! [`proto::GlobalStep::allowance`] is the executor side): an executor that joined at learner step
//! `s0` may have taken at most `warm_up_share + k × (learner_step − s0)` env steps, where k is
//! `env_steps_per_learner_step` and `warm_up_share = ceil(warm_up_transitions / live executors)`:
//! before its first update the learner waits for the replay minimum, which the live executors must
//! fill between them, so the share grows when one dies and nobody is held back by the dead. When
//! one joins the share shrinks, but an executor keeps the largest allowance it was granted (its side
//! of the rule), so nobody is put over an allowance it already used.
//! Optionally executors must not act with weights more than `max_weight_lag` published versions
//! behind the newest ([`proto::GlobalStep::min_weights_version`]).

use std::collections::BTreeMap;

use proto::{BarrierReport, GlobalStep};

/// The barrier's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BarrierRule {
    /// k: env steps allowed per learner step, per executor (the dissertation's text: 1).
    pub env_steps_per_learner_step: u64,
    /// Transitions the live executors may produce together before the learner's first step.
    pub warm_up_transitions: u64,
    /// Most published weight versions an executor may lag behind; `None` = no bound.
    pub max_weight_lag: Option<u64>,
}

/// Barrier state: the learner's step, recent weight versions and every live executor's last report.
#[derive(Debug, Clone)]
pub struct Barrier {
    rule: BarrierRule,
    learner_step: u64,
    /// Published weight versions, newest last (only as many as the lag bound needs).
    versions: Vec<u64>,
    /// Live executors and their latest report (`None` until the first one arrives).
    executors: BTreeMap<u32, Option<BarrierReport>>,
    /// Env steps granted on top of the warm-up share to break starvation (see [`Barrier::refill`]).
    refilled: u64,
}

impl Barrier {
    /// An empty barrier: learner at step 0, no weights, no executors.
    pub fn new(rule: BarrierRule) -> Self {
        Self { rule, learner_step: 0, versions: Vec::new(), executors: BTreeMap::new(), refilled: 0 }
    }

    /// The learner reached `step`. Returns whether the step moved: global steps never go back, so an
    /// older announcement (a learner restarted from an earlier checkpoint) is ignored until it catches up.
    pub fn learner_step(&mut self, step: u64) -> bool {
        let moved = step > self.learner_step;
        self.learner_step = self.learner_step.max(step);
        moved
    }

    /// New weights were published under `version`; older or repeated ones are ignored (returns false).
    pub fn published(&mut self, version: u64) -> bool {
        if self.versions.last().is_some_and(|&v| v >= version) {
            return false;
        }
        self.versions.push(version);
        let keep = self.rule.max_weight_lag.map_or(1, |l| l as usize + 1);
        if self.versions.len() > keep {
            self.versions.drain(..self.versions.len() - keep);
        }
        true
    }

    /// An executor became alive (its liveliness token appeared). Returns whether it is new.
    pub fn joined(&mut self, executor: u32) -> bool {
        let new = !self.executors.contains_key(&executor);
        self.executors.entry(executor).or_insert(None);
        new
    }

    /// An executor reported its progress. Only live executors (liveliness is the source of truth)
    /// are updated: a report still in flight when its sender died must not bring it back. Returns
    /// whether it was taken.
    pub fn report(&mut self, report: BarrierReport) -> bool {
        match self.executors.get_mut(&report.executor_id) {
            Some(slot) => {
                *slot = Some(report);
                true
            }
            None => false,
        }
    }

    /// An executor died or left: it no longer counts for the warm-up share. Returns whether it was known.
    pub fn left(&mut self, executor: u32) -> bool {
        self.executors.remove(&executor).is_some()
    }

    /// Live executors.
    pub fn executors(&self) -> usize {
        self.executors.len()
    }

    /// Every live executor and its latest report.
    pub fn reports(&self) -> impl Iterator<Item = (u32, Option<&BarrierReport>)> {
        self.executors.iter().map(|(id, report)| (*id, report.as_ref()))
    }

    /// Whether every live executor's latest report says it waits at the barrier as announced now,
    /// i.e. has used an allowance at least the current one (and at least one executor is known).
    /// Waiting for weights does not count, nor does a report sent before the latest step or refill
    /// reached its sender (or before the first announcement did): a refill would not help those.
    pub fn all_at_barrier(&self) -> bool {
        let now = self.announcement();
        let at_barrier = |r: &BarrierReport| {
            r.blocked
                && r.env_steps >= r.allowed_env_steps
                && r.allowed_env_steps >= now.allowance(r.joined_at)
        };
        !self.executors.is_empty() && self.executors.values().all(|r| r.as_ref().is_some_and(at_barrier))
    }

    /// Grants every executor another warm-up share: what a starved learner needs when the replay
    /// server lost its contents while executors wait for the learner (otherwise a deadlock).
    /// Returns the env steps granted per executor.
    pub fn refill(&mut self) -> u64 {
        let share = self.share();
        self.refilled += share;
        share
    }

    /// One live executor's part of the warm-up (the whole of it while none is known).
    fn share(&self) -> u64 {
        self.rule.warm_up_transitions.div_ceil(self.executors.len().max(1) as u64)
    }

    /// The learner's step as the barrier sees it.
    pub fn step(&self) -> u64 {
        self.learner_step
    }

    /// The oldest weight version executors may act with (0 without a lag bound or before enough
    /// versions exist).
    pub fn min_weights_version(&self) -> u64 {
        match self.rule.max_weight_lag {
            Some(lag) if self.versions.len() as u64 > lag => self.versions[0],
            _ => 0,
        }
    }

    /// The announcement for `control/step`.
    pub fn announcement(&self) -> GlobalStep {
        GlobalStep {
            learner_step: self.learner_step,
            weights_version: self.versions.last().copied().unwrap_or(0),
            env_steps_per_learner_step: self.rule.env_steps_per_learner_step,
            warm_up_share: self.share() + self.refilled,
            min_weights_version: self.min_weights_version(),
            live_executors: u32::try_from(self.executors.len()).unwrap_or(u32::MAX),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(k: u64, warm_up: u64, lag: Option<u64>) -> BarrierRule {
        BarrierRule { env_steps_per_learner_step: k, warm_up_transitions: warm_up, max_weight_lag: lag }
    }

    fn report(executor_id: u32, env_steps: u64) -> BarrierReport {
        BarrierReport {
            executor_id,
            env_steps,
            allowed_env_steps: env_steps,
            learner_step_seen: 0,
            joined_at: 0,
            weights_version: 0,
            blocked: false,
            blocked_ms_total: 0,
        }
    }

    #[test]
    fn executors_share_the_warm_up_then_get_k_steps_per_learner_step() {
        let mut b = Barrier::new(rule(1, 100, None));
        for id in 0..4 {
            assert!(b.joined(id));
        }
        assert_eq!(b.announcement().allowance(0), 25);
        assert!(b.learner_step(10));
        assert_eq!(b.announcement().allowance(0), 35);
        // A late joiner's allowance counts from its join.
        assert_eq!(b.announcement().allowance(10), 25);
        let mut k2 = Barrier::new(rule(2, 0, None));
        k2.joined(0);
        k2.learner_step(3);
        assert_eq!(k2.announcement().allowance(0), 6);
    }

    #[test]
    fn a_dead_executor_never_holds_the_others_back() {
        let mut b = Barrier::new(rule(1, 90, None));
        for id in 0..3 {
            b.joined(id);
            assert!(b.report(report(id, 30)));
        }
        // All three used their warm-up share; the learner cannot start until 90 are stored.
        assert_eq!(b.announcement().allowance(0), 30);
        assert!(b.left(2));
        assert!(!b.left(2));
        assert!(!b.report(report(2, 31)), "a late report from the dead does not revive it");
        // Two live executors now share the 90: each may go to 45.
        assert_eq!(b.announcement().allowance(0), 45);
        assert_eq!(b.announcement().live_executors, 2);
        assert_eq!(b.reports().map(|(id, _)| id).collect::<Vec<_>>(), vec![0, 1]);
    }

    #[test]
    fn no_executor_is_not_a_division_by_zero() {
        let b = Barrier::new(rule(1, 100, None));
        assert_eq!(b.announcement().warm_up_share, 100);
        assert_eq!(b.announcement().live_executors, 0);
    }

    #[test]
    fn the_lag_bound_sets_the_oldest_allowed_version() {
        let mut b = Barrier::new(rule(1, 1000, Some(1)));
        assert_eq!(b.min_weights_version(), 0);
        assert!(b.published(100));
        assert_eq!(b.min_weights_version(), 0, "one version: nobody can lag by more than 0");
        for v in [200, 300] {
            b.published(v);
        }
        assert_eq!(b.min_weights_version(), 200);
        assert!(!b.published(250)); // out of order: ignored
        assert_eq!(b.announcement().weights_version, 300);
        assert_eq!(b.announcement().min_weights_version, 200);
        let mut unbounded = Barrier::new(rule(1, 1000, None));
        unbounded.published(5);
        unbounded.published(9);
        assert_eq!(unbounded.min_weights_version(), 0);
    }

    #[test]
    fn a_refill_raises_every_allowance_by_a_share() {
        let mut b = Barrier::new(rule(1, 100, None));
        assert!(!b.all_at_barrier(), "no executors: nobody to unblock");
        b.joined(0);
        b.joined(1);
        b.report(BarrierReport { blocked: true, ..report(0, 50) });
        b.report(report(1, 50));
        assert!(!b.all_at_barrier());
        b.report(BarrierReport { blocked: true, allowed_env_steps: 60, ..report(1, 50) });
        assert!(!b.all_at_barrier(), "blocked below its allowance: waiting for weights, not the learner");
        b.report(BarrierReport { blocked: true, ..report(1, 50) });
        assert!(b.all_at_barrier());
        b.learner_step(7);
        assert!(!b.all_at_barrier(), "reports from before step 7 are not at today's barrier");
        assert_eq!(b.refill(), 50);
        assert_eq!(b.announcement().allowance(0), 50 + 50 + 7);
        for id in 0..2 {
            b.report(BarrierReport { blocked: true, ..report(id, 57) });
        }
        assert!(!b.all_at_barrier(), "sent before the refill reached them");
        for id in 0..2 {
            b.report(BarrierReport { blocked: true, ..report(id, 107) });
        }
        assert!(b.all_at_barrier());
        // Before any announcement an executor waits with nothing allowed: not at the barrier.
        let mut fresh = Barrier::new(rule(1, 100, None));
        fresh.joined(0);
        fresh.report(BarrierReport { blocked: true, ..report(0, 0) });
        assert!(!fresh.all_at_barrier());
    }

    #[test]
    fn the_global_step_never_goes_back() {
        let mut b = Barrier::new(rule(1, 0, None));
        assert!(b.learner_step(10));
        assert!(!b.learner_step(5));
        assert!(!b.learner_step(10));
        assert_eq!(b.step(), 10);
    }
}
