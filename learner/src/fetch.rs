//! The prefetch pipeline: `prefetch_batches` request loops, each with one sample request in flight,
//! so a batch is waiting whenever an update ends and the update thread never waits on the bus while
//! it could compute. Refusals and silences become a visible reason, and every request has a timeout.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use node::{Bus, Rejects, Shutdown};
use proto::{RejectCount, SampleReply, SampleRequest, Topic};
use tokio::sync::mpsc;

use crate::batch::Sampled;

/// Why the pipeline is not delivering, shared by the request loops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct FetchStatus {
    /// Batches received.
    pub batches: u64,
    /// Requests refused by the replay server, by reason (`below_min_size`, `rate_limited`, ...).
    pub refused: std::collections::BTreeMap<String, u64>,
    /// Requests nobody answered within the timeout (replay server down or restarting).
    pub unanswered: u64,
    /// Replies that did not decode, by `sample_reply/<reason>`.
    pub bad_replies: Vec<RejectCount>,
    /// Why no batch arrives now; cleared by the next batch.
    pub waiting: Option<Waiting>,
}

impl FetchStatus {
    /// Whether the learner has been starved of data for at least `after` at `now_ms` (Unix ms): the
    /// replay server refuses for lack of data. Not when it is down or slow: more env steps would
    /// not help then.
    pub fn starved(&self, now_ms: u64, after: Duration) -> bool {
        self.waiting
            .as_ref()
            .is_some_and(|w| w.for_data && now_ms.saturating_sub(w.since_ms) >= after.as_millis() as u64)
    }
}

/// Why the learner is waiting for batches, and since when.
#[derive(Debug, Clone, PartialEq)]
pub struct Waiting {
    /// What the replay server said, or that it said nothing.
    pub why: String,
    /// Since when (Unix ms).
    pub since_ms: u64,
    /// The replay server has too little data (below its minimum, or held to its samples-per-insert
    /// ratio): more env steps would help. Not so when it is down or slow.
    pub for_data: bool,
}

/// Shared state of the request loops.
#[derive(Debug, Default)]
pub struct Fetcher {
    status: Mutex<FetchStatus>,
    /// Undecodable replies: counted by reason, logged at most once per reason every few seconds
    /// (a flood of them once wrote a line per reply).
    bad_replies: Mutex<Rejects>,
    next_request: AtomicU64,
}

impl Fetcher {
    fn update(&self, f: impl FnOnce(&mut FetchStatus)) {
        f(&mut self.status.lock().unwrap_or_else(PoisonError::into_inner));
    }

    /// Records why no batch came. The wait keeps its start while its kind stays the same: a replay
    /// server filling up says "have 10", then "have 40", and that is one wait for data, not many.
    fn wait_reason(&self, why: String, for_data: bool) {
        self.update(|s| match &mut s.waiting {
            Some(w) if w.for_data == for_data => w.why = why,
            waiting => {
                tracing::info!(%why, "learner waiting for batches");
                *waiting = Some(Waiting { why, since_ms: node::unix_ms(), for_data });
            }
        });
    }

    fn bad_reply(&self, error: &proto::DecodeError) {
        self.bad_replies.lock().unwrap_or_else(PoisonError::into_inner).decode_failed("sample_reply", error);
    }

    /// Counts (and rate-limits the log of) an undecodable global-step announcement, beside the bad
    /// sample replies: both are the learner's rejected inputs.
    pub fn bad_announcement(&self, error: &proto::DecodeError) {
        self.bad_replies.lock().unwrap_or_else(PoisonError::into_inner).decode_failed("step", error);
    }

    /// The status now.
    pub fn status(&self) -> FetchStatus {
        let mut status = self.status.lock().unwrap_or_else(PoisonError::into_inner).clone();
        status.bad_replies = self.bad_replies.lock().unwrap_or_else(PoisonError::into_inner).to_report();
        status
    }
}

/// What one request loop needs.
#[derive(Debug, Clone)]
pub struct Requests {
    /// The bus.
    pub bus: Bus,
    /// Shared status and request ids.
    pub fetcher: Arc<Fetcher>,
    /// The learner step to put in requests.
    pub step: Arc<AtomicU64>,
    /// Transitions per batch.
    pub batch_size: u32,
    /// Batches per sample request (see `[learner] batches_per_request`).
    pub batches_per_request: u32,
    /// Per-request timeout.
    pub timeout: Duration,
    /// Keep IS weights (prioritized replay).
    pub prioritized: bool,
    /// Deterministic mode: the learner step of the next request, which its batches will be used
    /// at (one request loop; it moves on by `batches_per_request` per batch received).
    pub exact_step: Option<Arc<AtomicU64>>,
}

/// One request loop: ask, wait for the reply (bounded), hand the batch over; until shutdown or the
/// update thread hangs up.
pub async fn request_loop(r: Requests, batches: mpsc::Sender<Sampled>, mut shutdown: Shutdown) {
    loop {
        let step = r.exact_step.as_ref().unwrap_or(&r.step);
        let request = SampleRequest {
            request_id: r.fetcher.next_request.fetch_add(1, Ordering::Relaxed),
            learner_step: step.load(Ordering::Relaxed),
            batch_size: r.batch_size * r.batches_per_request,
        };
        let outcome = tokio::select! {
            _ = shutdown.wait() => return,
            outcome = ask(&r.bus, &request, r.timeout) => outcome,
        };
        let pause = match outcome {
            Asked::Reply(Ok(SampleReply::Batch(batch))) => {
                r.fetcher.update(|s| {
                    s.batches += 1;
                    s.waiting = None;
                });
                if let Some(next) = &r.exact_step {
                    next.fetch_add(u64::from(r.batches_per_request), Ordering::Relaxed);
                }
                let sampled = Sampled::from_wire(batch, r.prioritized);
                for part in sampled.split(r.batches_per_request as usize) {
                    tokio::select! {
                        _ = shutdown.wait() => return,
                        sent = batches.send(part) => if sent.is_err() { return },
                    }
                }
                continue;
            }
            Asked::Reply(Ok(SampleReply::Refused(refusal))) => {
                let name = refusal_name(&refusal.reason);
                r.fetcher.update(|s| *s.refused.entry(name.into()).or_default() += 1);
                let for_data = matches!(
                    refusal.reason,
                    proto::RefusalReason::BelowMinSize { .. } | proto::RefusalReason::RateLimited { .. }
                );
                r.fetcher.wait_reason(format!("replay server refused: {}", refusal.reason), for_data);
                Duration::from_millis(u64::from(refusal.retry_after_ms).clamp(10, 1000))
            }
            Asked::Reply(Err(error)) => {
                r.fetcher.bad_reply(&error);
                Duration::from_millis(100)
            }
            Asked::Error(why) => {
                r.fetcher.wait_reason(format!("replay server error: {why}"), false);
                Duration::from_millis(200)
            }
            Asked::Silence => {
                r.fetcher.update(|s| s.unanswered += 1);
                r.fetcher.wait_reason("replay server not answering (down or restarting)".into(), false);
                Duration::from_millis(200)
            }
        };
        tokio::select! {
            _ = shutdown.wait() => return,
            _ = tokio::time::sleep(pause) => {}
        }
    }
}

enum Asked {
    Reply(Result<SampleReply, proto::DecodeError>),
    Error(String),
    Silence,
}

async fn ask(bus: &Bus, request: &SampleRequest, timeout: Duration) -> Asked {
    match bus.query(Topic::ReplaySample, Some(proto::encode(request)), timeout).await {
        Ok(Some(Ok(payload))) => Asked::Reply(proto::decode(&payload.to_bytes())),
        Ok(Some(Err(error))) => Asked::Error(error),
        Ok(None) => Asked::Silence,
        Err(error) => Asked::Error(error.to_string()),
    }
}

fn refusal_name(reason: &proto::RefusalReason) -> &'static str {
    use proto::RefusalReason as R;
    match reason {
        R::BelowMinSize { .. } => "below_min_size",
        R::RateLimited { .. } => "rate_limited",
        R::BatchTooLarge { .. } => "batch_too_large",
        R::ShuttingDown => "shutting_down",
        R::Other { .. } => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wait_keeps_its_start_while_its_kind_stays() {
        let fetcher = Fetcher::default();
        let since = |f: &Fetcher| f.status().waiting.map(|w| (w.since_ms, w.for_data));
        fetcher.wait_reason("below min size 200 (have 10)".into(), true);
        fetcher.update(|s| s.waiting.as_mut().unwrap().since_ms = 1);
        fetcher.wait_reason("below min size 200 (have 40)".into(), true);
        assert_eq!(since(&fetcher), Some((1, true)));
        assert_eq!(fetcher.status().waiting.unwrap().why, "below min size 200 (have 40)");
        // The replay server going silent is another wait, and not one for data.
        fetcher.wait_reason("replay server not answering".into(), false);
        let (started, for_data) = since(&fetcher).unwrap();
        assert!(started > 1 && !for_data);
        assert!(!fetcher.status().starved(started + 5000, Duration::from_secs(1)), "down is not starved");
    }

    #[test]
    fn undecodable_replies_are_counted_by_reason() {
        let fetcher = Fetcher::default();
        let error = proto::decode::<SampleReply>(b"not a reply").unwrap_err();
        for _ in 0..741 {
            fetcher.bad_reply(&error);
        }
        let reason = format!("sample_reply/{}", error.reason());
        assert_eq!(fetcher.status().bad_replies, vec![RejectCount { reason, count: 741 }]);
    }

    #[test]
    fn starved_after_a_lasting_wait_for_data() {
        let fetcher = Fetcher::default();
        fetcher.wait_reason("below min size 200 (have 0)".into(), true);
        let since = fetcher.status().waiting.unwrap().since_ms;
        let after = Duration::from_secs(1);
        assert!(!fetcher.status().starved(since + 999, after));
        assert!(fetcher.status().starved(since + 1000, after));
    }
}
