//! Observability: one generic stats report per process and role, and per-episode results.
//!
//! Stats are named metrics rather than a struct per role, so the monitor needs no change when a role
//! adds a figure; the contract is the naming scheme `<role>/<name>` with units in the name
//! (`learner/updates_per_s`, `executor/env_steps_per_s`, `replay/size_transitions`).

use serde::{Deserialize, Serialize};

use crate::check::{self, MAX_STATS_ENTRIES};
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;
use crate::topics::{NodeId, Role};

/// One named figure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metric {
    /// `<role>/<name>` where `<role>` is the report's role; ASCII letters, digits, `_ . / -`, ≤ 128 bytes.
    pub name: String,
    /// The value; finite.
    pub value: f64,
}

/// Something the process is waiting on right now, so stalls explain themselves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockedReason {
    /// What waits, as a name (`executor/barrier`, `learner/sample`).
    pub what: String,
    /// Why, in words (`learner at step 120, k = 1000, env steps 121000`).
    pub why: String,
    /// Since when, in Unix milliseconds.
    pub since_ms: u64,
}

/// How many inputs were rejected for one reason since the process started.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejectCount {
    /// The reason, as a name (`decode/checksum`, `experience/stale_weights`).
    pub reason: String,
    /// Cumulative count.
    pub count: u64,
}

/// A process's periodic report on `stats/<role>/<id>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatsReport {
    /// The reporting role.
    pub role: Role,
    /// Its id within the role.
    pub id: u32,
    /// Wall-clock time of the report, Unix milliseconds.
    pub unix_ms: u64,
    /// Named figures; names should be unique within a report.
    pub metrics: Vec<Metric>,
    /// What the process is blocked on now; empty when it is making progress.
    pub blocked: Vec<BlockedReason>,
    /// Cumulative rejections by reason.
    pub rejected: Vec<RejectCount>,
}

impl StatsReport {
    /// An empty report from `node` at `unix_ms`.
    pub fn new(node: NodeId, unix_ms: u64) -> StatsReport {
        StatsReport {
            role: node.role,
            id: node.id,
            unix_ms,
            metrics: Vec::new(),
            blocked: Vec::new(),
            rejected: Vec::new(),
        }
    }

    /// The reporting process.
    pub fn node(&self) -> NodeId {
        NodeId { role: self.role, id: self.id }
    }

    /// Appends a metric (checked on validation, not here, so a report is built without `?` per line).
    pub fn push_metric(&mut self, name: impl Into<String>, value: f64) {
        self.metrics.push(Metric { name: name.into(), value });
    }

    /// The value of the last metric called `name`.
    pub fn metric(&self, name: &str) -> Option<f64> {
        self.metrics.iter().rev().find(|m| m.name == name).map(|m| m.value)
    }
}

impl Sealed for StatsReport {}

impl Message for StatsReport {
    const KIND: MessageKind = MessageKind::StatsReport;

    fn validate(&self) -> Result<(), ValidationError> {
        check::at_most("metrics", self.metrics.len(), MAX_STATS_ENTRIES)?;
        check::at_most("blocked", self.blocked.len(), MAX_STATS_ENTRIES)?;
        check::at_most("rejected", self.rejected.len(), MAX_STATS_ENTRIES)?;
        let role = self.role.as_str();
        for (index, metric) in self.metrics.iter().enumerate() {
            check::name("metric name", &metric.name)?;
            let in_scheme = metric.name.strip_prefix(role).and_then(|rest| rest.strip_prefix('/'));
            if in_scheme.is_none_or(str::is_empty) {
                return Err(check::bad_text(
                    "metric name",
                    &metric.name,
                    "must be <role>/<name> for its role",
                ));
            }
            if !metric.value.is_finite() {
                return Err(ValidationError::NonFinite { field: "metrics", index });
            }
        }
        for blocked in &self.blocked {
            check::name("blocked what", &blocked.what)?;
            check::text("blocked why", &blocked.why)?;
        }
        for rejected in &self.rejected {
            check::name("rejected reason", &rejected.reason)?;
        }
        Ok(())
    }
}

/// A finished episode on `episodes/<executor_id>`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpisodeReport {
    /// The executor that ran it.
    pub executor_id: u32,
    /// Episode index within that executor, from 0.
    pub episode: u64,
    /// Undiscounted sum of rewards; finite.
    pub episode_return: f64,
    /// Environment steps in the episode; positive.
    pub length: u32,
    /// Whether the environment terminated it (the Ant fell) rather than the time limit.
    pub terminated: bool,
    /// The executor's cumulative environment steps at the episode's end.
    pub env_steps: u64,
    /// Weights version in use at the episode's end.
    pub weights_version: u64,
}

impl Sealed for EpisodeReport {}

impl Message for EpisodeReport {
    const KIND: MessageKind = MessageKind::EpisodeReport;

    fn validate(&self) -> Result<(), ValidationError> {
        check::finite_f64("episode_return", self.episode_return)?;
        check::positive("length", u64::from(self.length))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report() -> StatsReport {
        let mut r = StatsReport::new(NodeId { role: Role::Learner, id: 0 }, 1_700_000_000_000);
        r.push_metric("learner/updates_per_s", 612.5);
        r.push_metric("learner/q_loss", 0.25);
        r
    }

    #[test]
    fn metric_names_follow_the_role_scheme() {
        assert_eq!(report().validate(), Ok(()));
        assert_eq!(report().metric("learner/q_loss"), Some(0.25));
        for bad in ["replay/size", "learner/", "learner", "learnerx/a", "learner/has space", ""] {
            let mut r = report();
            r.push_metric(bad, 1.0);
            assert!(matches!(r.validate(), Err(ValidationError::BadText { .. })), "{bad:?} accepted");
        }
        let mut inf = report();
        inf.push_metric("learner/alpha", f64::INFINITY);
        assert!(matches!(inf.validate(), Err(ValidationError::NonFinite { .. })));
    }

    #[test]
    fn blocked_and_rejected_are_checked() {
        let mut r = report();
        r.blocked.push(BlockedReason {
            what: "learner/sample".into(),
            why: "below\nmin".into(),
            since_ms: 0,
        });
        assert!(matches!(r.validate(), Err(ValidationError::BadText { field: "blocked why", .. })));
        let mut r = report();
        r.rejected.push(RejectCount { reason: String::new(), count: 3 });
        assert!(matches!(r.validate(), Err(ValidationError::BadText { field: "rejected reason", .. })));
        let mut r = report();
        r.metrics =
            (0..=MAX_STATS_ENTRIES).map(|i| Metric { name: format!("learner/m{i}"), value: 0.0 }).collect();
        assert!(matches!(r.validate(), Err(ValidationError::TooLarge { field: "metrics", .. })));
    }

    #[test]
    fn episode_report_checks() {
        let ep = EpisodeReport {
            executor_id: 1,
            episode: 0,
            episode_return: 1200.0,
            length: 1000,
            terminated: false,
            env_steps: 1000,
            weights_version: 0,
        };
        assert_eq!(ep.validate(), Ok(()));
        assert!(EpisodeReport { episode_return: f64::NAN, ..ep }.validate().is_err());
        assert_eq!(
            EpisodeReport { length: 0, ..ep }.validate(),
            Err(ValidationError::Zero { field: "length" })
        );
    }
}
