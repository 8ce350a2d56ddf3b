//! The global-step barrier, sans-IO: how many env steps each executor may have taken, given the
//! learner's global step, and whether its weights are fresh enough to act with.
//!
//! Rule (the dissertation's "one executor step per learner step", made exact and per executor):
//! executor i may have taken at most `warm_up_i + k × learner_step` env steps, where k is
//! `max_env_steps_per_learner_step` and `warm_up_i = ceil(warm_up_transitions / live executors)`:
//! before its first update the learner waits for the replay minimum, which the live executors must
//! fill between them, so the warm-up share grows when one dies and nobody is held back by the dead.
//! Optionally an executor must not act with weights more than `max_weight_lag` published versions
//! behind the newest.

use std::collections::BTreeMap;

/// The barrier's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BarrierRule {
    /// k: env steps allowed per learner step, per executor (the dissertation's text: 1).
    pub max_env_steps_per_learner_step: u64,
    /// Transitions the live executors may produce together before the learner's first step.
    pub warm_up_transitions: u64,
    /// Most published weight versions an executor may lag behind; `None` = no bound.
    pub max_weight_lag: Option<u64>,
}

/// What one executor may do now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Permit {
    /// It may step until its cumulative env-step count reaches `until`.
    Go {
        /// Cumulative env steps allowed.
        until: u64,
    },
    /// It must wait, for this reason.
    Wait(WaitReason),
}

/// Why an executor waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitReason {
    /// It has used its allowance; the learner must step first.
    AheadOfLearner {
        /// Its env steps.
        env_steps: u64,
        /// Its allowance at the current learner step.
        allowed: u64,
    },
    /// Its weights are too old; it must fetch newer ones first.
    StaleWeights {
        /// Published versions newer than its own.
        lag: u64,
        /// The configured bound.
        max: u64,
    },
}

/// What the barrier knows of one executor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct ExecutorState {
    env_steps: u64,
    weights_version: u64,
}

/// Barrier state for every live executor, advanced by global steps and weight versions.
#[derive(Debug, Clone)]
pub struct Barrier {
    rule: BarrierRule,
    learner_step: u64,
    /// Published weight versions, newest last (only as many as the lag bound needs).
    versions: Vec<u64>,
    executors: BTreeMap<u32, ExecutorState>,
}

impl Barrier {
    /// An empty barrier: learner at step 0, no weights, no executors.
    pub fn new(rule: BarrierRule) -> Self {
        Self { rule, learner_step: 0, versions: Vec::new(), executors: BTreeMap::new() }
    }

    /// The learner reached `step` (global steps never go back; an older announcement is ignored).
    pub fn learner_step(&mut self, step: u64) {
        self.learner_step = self.learner_step.max(step);
    }

    /// New weights were published under `version` (a global step); older or repeated ones are ignored.
    pub fn published(&mut self, version: u64) {
        if self.versions.last().is_some_and(|&v| v >= version) {
            return;
        }
        self.versions.push(version);
        let keep = self.rule.max_weight_lag.map_or(1, |l| l as usize + 1);
        if self.versions.len() > keep {
            self.versions.drain(..self.versions.len() - keep);
        }
    }

    /// An executor reported its progress (it joins if new). Counters never go back.
    pub fn report(&mut self, executor: u32, env_steps: u64, weights_version: u64) {
        let state = self.executors.entry(executor).or_default();
        state.env_steps = state.env_steps.max(env_steps);
        state.weights_version = state.weights_version.max(weights_version);
    }

    /// An executor died or left: it no longer counts for the warm-up share.
    pub fn left(&mut self, executor: u32) {
        self.executors.remove(&executor);
    }

    /// Live executors.
    pub fn executors(&self) -> usize {
        self.executors.len()
    }

    /// Env steps executor `executor` may have taken by now.
    pub fn allowance(&self, executor: u32) -> u64 {
        let live = self.executors.len().max(1) as u64;
        // The asking executor counts even before its first report.
        let live = if self.executors.contains_key(&executor) { live } else { live + 1 };
        self.rule.warm_up_transitions.div_ceil(live)
            + self.rule.max_env_steps_per_learner_step * self.learner_step
    }

    /// What `executor`, at `env_steps` with weights `weights_version`, may do now.
    pub fn permit(&self, executor: u32, env_steps: u64, weights_version: u64) -> Permit {
        if let Some(max) = self.rule.max_weight_lag {
            let lag = self.versions.iter().filter(|&&v| v > weights_version).count() as u64;
            if lag > max {
                return Permit::Wait(WaitReason::StaleWeights { lag, max });
            }
        }
        let allowed = self.allowance(executor);
        if env_steps >= allowed {
            Permit::Wait(WaitReason::AheadOfLearner { env_steps, allowed })
        } else {
            Permit::Go { until: allowed }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(k: u64, warm_up: u64, lag: Option<u64>) -> BarrierRule {
        BarrierRule { max_env_steps_per_learner_step: k, warm_up_transitions: warm_up, max_weight_lag: lag }
    }

    #[test]
    fn executors_share_the_warm_up_then_get_k_steps_per_learner_step() {
        let mut b = Barrier::new(rule(1, 100, None));
        for id in 0..4 {
            b.report(id, 0, 0);
        }
        assert_eq!(b.permit(0, 0, 0), Permit::Go { until: 25 });
        assert_eq!(
            b.permit(0, 25, 0),
            Permit::Wait(WaitReason::AheadOfLearner { env_steps: 25, allowed: 25 })
        );
        b.learner_step(10);
        assert_eq!(b.permit(0, 25, 0), Permit::Go { until: 35 });
        let mut k2 = Barrier::new(rule(2, 0, None));
        k2.report(0, 0, 0);
        k2.learner_step(3);
        assert_eq!(k2.permit(0, 5, 0), Permit::Go { until: 6 });
        assert!(matches!(k2.permit(0, 6, 0), Permit::Wait(_)));
    }

    #[test]
    fn a_dead_executor_never_holds_the_others_back() {
        let mut b = Barrier::new(rule(1, 90, None));
        for id in 0..3 {
            b.report(id, 30, 0);
        }
        // All three used their warm-up share; the learner cannot start until 90 are stored.
        assert!(matches!(b.permit(0, 30, 0), Permit::Wait(_)));
        b.left(2);
        // Two live executors now share the 90: each may go to 45.
        assert_eq!(b.permit(0, 30, 0), Permit::Go { until: 45 });
        assert_eq!(b.executors(), 2);
    }

    #[test]
    fn a_newcomer_counts_itself_before_its_first_report() {
        let mut b = Barrier::new(rule(1, 100, None));
        b.report(0, 0, 0);
        assert_eq!(b.allowance(1), 50);
        assert_eq!(b.allowance(0), 100);
    }

    #[test]
    fn stale_weights_wait_when_a_lag_bound_is_set() {
        let mut b = Barrier::new(rule(1, 1000, Some(1)));
        b.report(0, 0, 0);
        for v in [100, 200, 300] {
            b.published(v);
        }
        assert_eq!(b.permit(0, 0, 200), Permit::Go { until: 1000 });
        assert_eq!(b.permit(0, 0, 100), Permit::Wait(WaitReason::StaleWeights { lag: 2, max: 1 }));
        b.published(250); // out of order: ignored
        assert_eq!(b.permit(0, 0, 200), Permit::Go { until: 1000 });
        let unbounded = Barrier::new(rule(1, 1000, None));
        assert!(matches!(unbounded.permit(0, 0, 0), Permit::Go { .. }));
    }

    #[test]
    fn counters_and_steps_never_go_back() {
        let mut b = Barrier::new(rule(1, 0, None));
        b.learner_step(10);
        b.learner_step(5);
        assert_eq!(b.allowance(0), 10);
        b.report(0, 8, 3);
        b.report(0, 2, 1);
        assert_eq!(b.executors[&0], ExecutorState { env_steps: 8, weights_version: 3 });
    }
}
