//! The stats report on `stats/replay/<id>`: sizes, rates, priority digest, limiter state, time
//! blocked and why, rejections by reason, snapshot and memory figures. Metric names follow
//! `replay/<name>` with units in the name.

use std::time::Instant;

use proto::{BlockedReason, NodeId, RejectCount, StatsReport};

use crate::replica::SnapshotLog;
use crate::scan::PriorityDigest;
use crate::service::{Service, ServiceCounters};

/// Per-second rates from counter differences between two reports.
#[derive(Debug, Clone)]
pub struct RateMeter {
    at: Instant,
    last: ServiceCounters,
}

/// Rates over the last interval.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Rates {
    /// Transitions inserted per second.
    pub inserts_per_s: f64,
    /// Experience messages per second.
    pub insert_messages_per_s: f64,
    /// Batches served per second.
    pub batches_per_s: f64,
    /// Transitions served per second.
    pub sampled_transitions_per_s: f64,
    /// Priority updates (applied or stale) per second.
    pub priority_updates_per_s: f64,
}

impl RateMeter {
    /// A meter starting from `counters` at `now`.
    pub fn new(counters: &ServiceCounters, now: Instant) -> Self {
        Self { at: now, last: counters.clone() }
    }

    /// Rates since the previous call (or creation).
    pub fn rates(&mut self, counters: &ServiceCounters, now: Instant) -> Rates {
        let dt = now.duration_since(self.at).as_secs_f64().max(1e-9);
        let per_s = |new: u64, old: u64| new.saturating_sub(old) as f64 / dt;
        let (c, l) = (counters, &self.last);
        let rates = Rates {
            inserts_per_s: per_s(c.inserted_transitions, l.inserted_transitions),
            insert_messages_per_s: per_s(c.insert_messages, l.insert_messages),
            batches_per_s: per_s(c.sampled_batches, l.sampled_batches),
            sampled_transitions_per_s: per_s(c.sampled_transitions, l.sampled_transitions),
            priority_updates_per_s: per_s(
                c.priorities_applied + c.priorities_stale,
                l.priorities_applied + l.priorities_stale,
            ),
        };
        *self = Self::new(counters, now);
        rates
    }
}

/// Everything a report is built from besides the service.
#[derive(Debug, Clone)]
pub struct ReportInputs<'a> {
    /// The reporting node.
    pub node: NodeId,
    /// Wall-clock time, Unix ms.
    pub unix_ms: u64,
    /// Rates over the last interval.
    pub rates: Rates,
    /// Priority digest from the last scan.
    pub digest: Option<&'a PriorityDigest>,
    /// Snapshot figures, when snapshots are on.
    pub snapshots: Option<&'a SnapshotLog>,
    /// The planned memory (config's memory plan), bytes.
    pub memory_planned_bytes: u64,
}

/// Builds the report (valid for `proto`'s checks: names in the role's scheme, finite values).
pub fn build(service: &Service, inputs: &ReportInputs<'_>) -> StatsReport {
    let mut report = StatsReport::new(inputs.node, inputs.unix_ms);
    let mut metric = |name: &str, value: f64| {
        if value.is_finite() {
            report.push_metric(format!("replay/{name}"), value);
        }
    };
    let buffer = service.buffer();
    let c = service.counters();
    metric("size_transitions", buffer.len() as f64);
    metric("capacity_transitions", buffer.capacity() as f64);
    metric("inserted_transitions_total", c.inserted_transitions as f64);
    metric("sampled_batches_total", c.sampled_batches as f64);
    metric("sampled_transitions_total", c.sampled_transitions as f64);
    metric("priority_updates_applied_total", c.priorities_applied as f64);
    metric("priority_updates_stale_total", c.priorities_stale as f64);
    metric("evicted_early_total", buffer.counters().evicted_early as f64);
    metric("duplicate_batches_total", c.duplicate_batches as f64);
    metric("duplicate_transitions_total", c.duplicate_transitions as f64);
    metric("streams", service.streams().len() as f64);
    let r = inputs.rates;
    metric("inserts_per_s", r.inserts_per_s);
    metric("insert_messages_per_s", r.insert_messages_per_s);
    metric("batches_per_s", r.batches_per_s);
    metric("sampled_transitions_per_s", r.sampled_transitions_per_s);
    metric("priority_updates_per_s", r.priority_updates_per_s);
    if let Some(d) = inputs.digest {
        metric("priority_min", d.min);
        metric("priority_max", d.max);
        metric("priority_mean", d.mean);
        metric("ess", d.ess);
    }
    let limiter = service.limiter();
    metric("samples_per_insert", limiter.observed_ratio());
    if let Some(allowance) = limiter.sample_allowance() {
        metric("sample_allowance_transitions", allowance);
    }
    metric("pending_requests", service.waiting().map_or(0, |w| w.count) as f64);
    for (key, ms) in &c.blocked_ms {
        metric(&format!("blocked_ms_total.{key}"), *ms as f64);
    }
    for (key, n) in &c.refused {
        metric(&format!("refused_total.{key}"), *n as f64);
    }
    metric("rejected_total", service.rejects().total() as f64);
    if let Some(lockstep) = service.lockstep() {
        metric("lockstep.cut", lockstep.last_cut() as f64);
        metric("lockstep.cuts", f64::from(u8::from(lockstep.cuts())));
    }
    metric("memory_planned_bytes", inputs.memory_planned_bytes as f64);
    if let Some(replica) = service.replica() {
        metric("replica_lag_bytes", replica.lag_bytes() as f64);
    }
    if let Some(s) = inputs.snapshots {
        metric("snapshots_written_total", s.written as f64);
        metric("snapshots_failed_total", s.failed as f64);
        metric("snapshots_aborted_total", s.aborted as f64);
        metric("snapshot_last_sequence", s.last_sequence as f64);
        // Read with the counters: a snapshot numbered above it holds everything they count.
        metric("snapshot_requested_sequence", service.snapshot_sequence() as f64);
        metric("snapshot_last_serialise_ms", s.last_serialise_ms);
        metric("snapshot_last_bytes", s.last_bytes as f64);
    }
    if let Some(w) = service.waiting() {
        report.blocked.push(BlockedReason {
            what: "replay/sample".into(),
            why: format!("{} ({} requests waiting)", w.why, w.count),
            since_ms: w.since_unix_ms,
        });
    }
    if let Some(w) = service.insert_wait() {
        report.blocked.push(BlockedReason {
            what: "replay/insert".into(),
            why: w.why.clone(),
            since_ms: w.since_unix_ms,
        });
    }
    report.rejected = service
        .rejects()
        .counts()
        .iter()
        .map(|(reason, &count)| RejectCount { reason: reason.clone(), count })
        .collect();
    report
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn rates_are_differences_over_time() {
        let t0 = Instant::now();
        let mut counters = ServiceCounters::default();
        let mut meter = RateMeter::new(&counters, t0);
        counters.inserted_transitions = 640;
        counters.insert_messages = 10;
        counters.sampled_batches = 4;
        let rates = meter.rates(&counters, t0 + Duration::from_millis(500));
        assert_eq!(rates.inserts_per_s, 1280.0);
        assert_eq!(rates.insert_messages_per_s, 20.0);
        assert_eq!(rates.batches_per_s, 8.0);
        let again = meter.rates(&counters, t0 + Duration::from_secs(1));
        assert_eq!(again.inserts_per_s, 0.0);
    }
}
