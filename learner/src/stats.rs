//! The learner's stats report (`stats/learner/<id>`).

use proto::{BlockedReason, EvalReport, NodeId, RejectCount, StatsReport};

use crate::{FetchStatus, Progress};

/// The report: updates/s, losses, the pipeline's waiting, the last evaluation.
pub(crate) fn report(
    node: NodeId,
    p: &Progress,
    fetch: &FetchStatus,
    eval: Option<EvalReport>,
) -> StatsReport {
    let mut r = StatsReport::new(node, node::unix_ms());
    r.push_metric("learner/learner_step", p.learner_step as f64);
    r.push_metric("learner/updates_per_s", p.updates_per_s);
    r.push_metric("learner/wait_fraction", p.wait_fraction);
    r.push_metric("learner/wait_ms_total", p.wait_ms_total as f64);
    r.push_metric("learner/weights_version", p.weights_version as f64);
    r.push_metric("learner/evals_skipped", p.evals_skipped as f64);
    r.push_metric("learner/non_finite_updates", p.non_finite_updates as f64);
    // 1: the fused learner runs the updates; 0: candle (the log says why at start).
    r.push_metric("learner/backend_fused", if p.fused { 1.0 } else { 0.0 });
    if p.means.n > 0 {
        r.push_metric("learner/q_loss", p.means.q_loss);
        r.push_metric("learner/v_loss", p.means.v_loss);
        r.push_metric("learner/policy_loss", p.means.policy_loss);
        r.push_metric("learner/mean_q", p.means.mean_q);
        r.push_metric("learner/mean_log_prob", p.means.mean_log_prob);
        r.push_metric("learner/temperature", p.means.temperature);
    }
    r.push_metric("learner/batches_received", fetch.batches as f64);
    r.push_metric("learner/samples_unanswered", fetch.unanswered as f64);
    if let Some(e) = eval {
        r.push_metric("learner/eval_return", e.mean_return);
        r.push_metric("learner/eval_epoch", e.epoch as f64);
    }
    if let Some(waiting) = &fetch.waiting {
        r.blocked.push(BlockedReason {
            what: "learner/sample".into(),
            why: waiting.why.clone(),
            since_ms: waiting.since_ms,
        });
    }
    r.rejected = fetch
        .refused
        .iter()
        .map(|(reason, count)| RejectCount { reason: format!("sample_refused/{reason}"), count: *count })
        .collect();
    r.rejected.extend(fetch.bad_replies.iter().cloned());
    r
}
