//! Bad input: counts by reason, and warnings that stay readable in a flood (one line per reason per
//! interval, with the number suppressed). Every role keeps one and publishes the counts in its stats.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use proto::{DecodeError, RejectCount};

/// Minimum time between two warnings for the same reason; every rate-limited warning of the roles
/// uses it (the learner's "non-finite loss" too), so a flood reads the same in every log.
pub const WARN_EVERY: Duration = Duration::from_secs(5);

#[derive(Debug, Clone)]
struct WarnState {
    last: Instant,
    suppressed: u64,
}

/// Rejection counts by reason (`<input>/<reason>`, e.g. `experience/checksum`) and the warning rate limit.
#[derive(Debug, Clone, Default)]
pub struct Rejects {
    counts: BTreeMap<String, u64>,
    warned: BTreeMap<String, WarnState>,
}

impl Rejects {
    /// Starts from restored counts.
    pub fn from_counts(counts: BTreeMap<String, u64>) -> Self {
        Self { counts, warned: BTreeMap::new() }
    }

    /// Counts one rejection under `key` and logs it, unless this key was logged less than 5 s before `now`.
    pub fn record(&mut self, key: &str, detail: &str, now: Instant) {
        *self.counts.entry(key.to_string()).or_default() += 1;
        match self.warned.get_mut(key) {
            Some(state) if now.duration_since(state.last) < WARN_EVERY => state.suppressed += 1,
            Some(state) => {
                tracing::warn!(reason = %key, %detail, suppressed = state.suppressed, "rejected input");
                *state = WarnState { last: now, suppressed: 0 };
            }
            None => {
                tracing::warn!(reason = %key, %detail, "rejected input");
                self.warned.insert(key.to_string(), WarnState { last: now, suppressed: 0 });
            }
        }
    }

    /// Counts a message on `input` that failed to decode, as `<input>/<decode reason>`.
    pub fn decode_failed(&mut self, input: &str, error: &DecodeError) {
        self.record(&format!("{input}/{}", error.reason()), &error.to_string(), Instant::now());
    }

    /// Cumulative counts by reason.
    pub fn counts(&self) -> &BTreeMap<String, u64> {
        &self.counts
    }

    /// Total rejections of all reasons.
    pub fn total(&self) -> u64 {
        self.counts.values().sum()
    }

    /// The counts as a stats report's `rejected` list.
    pub fn to_report(&self) -> Vec<RejectCount> {
        self.counts
            .iter()
            .map(|(reason, count)| RejectCount { reason: reason.clone(), count: *count })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_by_reason_and_reports_them() {
        let mut r = Rejects::default();
        let now = Instant::now();
        r.record("weights/checksum", "x", now);
        r.record("weights/checksum", "x", now);
        r.decode_failed("step", &DecodeError::Malformed("bad".into()));
        assert_eq!(r.total(), 3);
        assert_eq!(r.counts()["weights/checksum"], 2);
        assert_eq!(r.to_report()[0], RejectCount { reason: "step/malformed".into(), count: 1 });
    }

    #[test]
    fn counts_every_rejection_but_warns_once_per_interval() {
        let mut rejects = Rejects::default();
        let now = Instant::now();
        for i in 0..1000 {
            rejects.record("experience/checksum", "crc", now + Duration::from_millis(i));
        }
        assert_eq!(rejects.counts().get("experience/checksum"), Some(&1000));
        assert_eq!(rejects.warned["experience/checksum"].suppressed, 999);
        rejects.record("experience/checksum", "crc", now + Duration::from_secs(6));
        assert_eq!(rejects.warned["experience/checksum"].suppressed, 0);
        assert_eq!(rejects.total(), 1001);
    }
}
