//! The executor's stats report (`stats/executor/<id>`).

use node::Rejects;
use proto::{BlockedReason, NodeId, StatsReport};

use crate::spool::SpoolCounts;
use crate::worker::Progress;

/// The report for `progress`: throughput, weights and their lag, the barrier, what it waits on.
pub(crate) fn report(
    node: NodeId,
    progress: &Progress,
    rejects: &Rejects,
    spool: Option<SpoolCounts>,
) -> StatsReport {
    let mut r = StatsReport::new(node, node::unix_ms());
    let p = progress;
    r.push_metric("executor/env_steps", p.env_steps as f64);
    r.push_metric("executor/env_steps_per_s", p.env_steps_per_s);
    r.push_metric("executor/episodes", p.episodes as f64);
    if let Some(ret) = p.last_return {
        r.push_metric("executor/last_return", ret);
    }
    r.push_metric("executor/allowed_env_steps", p.allowed_env_steps as f64);
    r.push_metric("executor/weights_loads", p.weights_loads as f64);
    r.push_metric("executor/weights_unloadable", p.weights_unloadable as f64);
    r.push_metric("executor/batches", p.batches as f64);
    r.push_metric("executor/dropped_non_finite", p.dropped_non_finite as f64);
    r.push_metric("executor/dropped_n_step_tail", p.dropped_n_step_tail as f64);
    r.push_metric("executor/blocked_ms_total", p.blocked_ms_total as f64);
    r.push_metric("executor/blocked", if p.waiting.is_some() { 1.0 } else { 0.0 });
    if let Some(version) = p.weights_version {
        r.push_metric("executor/weights_version", version as f64);
        if let Some(step) = p.step {
            // Versions behind the newest published, and learner steps behind the learner.
            r.push_metric("executor/weights_lag_steps", step.weights_version.saturating_sub(version) as f64);
            r.push_metric("executor/policy_lag_steps", step.learner_step.saturating_sub(version) as f64);
        }
    }
    if let Some(step) = p.step {
        r.push_metric("executor/learner_step_seen", step.learner_step as f64);
    }
    if let Some(c) = spool {
        let figures = [
            ("held_batches", c.held_batches),
            ("held_bytes", c.held_bytes),
            ("produced_transitions", c.produced_transitions),
            ("durable_batches", c.durable_batches),
            ("resent_batches", c.resent_batches),
            ("overflow_batches", c.overflow_batches),
            ("invalid_batches", c.invalid_batches),
            ("write_failed_batches", c.write_failed_batches),
            ("ledger_backlog", c.ledger_backlog),
        ];
        for (name, value) in figures {
            r.push_metric(format!("executor/spool_{name}"), value as f64);
        }
    }
    if let Some(w) = &p.waiting {
        r.blocked.push(BlockedReason { what: w.wait.what().into(), why: w.wait.why(), since_ms: w.since_ms });
    }
    r.rejected = rejects.to_report();
    r
}
