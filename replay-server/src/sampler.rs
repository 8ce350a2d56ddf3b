//! The query side: `replay/sample` (serve, or hold until inserts lift the block or the deadline
//! passes, then refuse with a reason and a retry hint; never a silent hang), `replay/state`
//! (stats plus the top-k priorities, on demand) and `replay/cut` (deterministic mode's newest cut).
//!
//! Replies are `express`: without it zenoh's batching timer adds about a millisecond to a ~115 KB
//! reply, which would cap a synchronous learner below 1,000 batches/s. A query's final message goes
//! out when the `Query` is dropped, so every path drops it right after replying.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use node::Queryable;
use node::Shutdown;
use proto::{RefusalReason, SampleRefusal, SampleReply};
use zenoh::query::Query;

use crate::config::MAX_TOP_K;
use crate::limiter::Blocked;
use crate::pending::{Pending, Waiter};

use crate::server::{Ctx, scan, unix_ms_of};
use crate::service::{SampleOutcome, Waiting};
use crate::stats::Rates;

type QueryQueue = Queryable;

/// Far enough ahead to mean "no deadline" for `sleep_until`.
const IDLE: Duration = Duration::from_secs(3600);

pub(crate) async fn sample_loop(
    ctx: Arc<Ctx>,
    queries: QueryQueue,
    mut shutdown: Shutdown,
) -> anyhow::Result<()> {
    let wait = Duration::from_millis(ctx.cfg.request_deadline_ms);
    let mut pending: Pending<Query> = Pending::new(ctx.cfg.max_pending_requests as usize, wait);
    loop {
        let wake = pending.next_deadline().unwrap_or_else(|| Instant::now() + IDLE);
        tokio::select! {
            biased;
            _ = shutdown.wait() => break,
            received = queries.recv() => match received {
                Ok(query) => on_query(&ctx, &mut pending, query).await,
                Err(_) => break,
            },
            _ = ctx.inserted.notified(), if !pending.is_empty() => {}
            _ = tokio::time::sleep_until(wake.into()), if !pending.is_empty() => {}
        }
        serve_pending(&ctx, &mut pending).await;
        expire(&ctx, &mut pending).await;
        publish_waiting(&ctx, &pending);
        // As in the insert loop: a ready channel never yields by itself.
        tokio::task::yield_now().await;
    }
    for waiter in pending.drain_all() {
        finish_wait(&ctx, &waiter, "shutting_down");
        refuse(&waiter.ticket, waiter.request.request_id, RefusalReason::ShuttingDown, 0).await;
    }
    ctx.lock().set_waiting(None);
    Ok(())
}

async fn on_query(ctx: &Ctx, pending: &mut Pending<Query>, query: Query) {
    let now = Instant::now();
    let payload = query.payload().map(|p| p.to_bytes());
    let decoded = ctx.lock().decode_request(payload.as_deref(), now);
    let request = match decoded {
        Ok(request) => request,
        Err(rejection) => {
            if let Err(e) = query.reply_err(format!("bad sample request: {}", rejection.detail)).await {
                tracing::debug!(error = %e, "could not send an error reply");
            }
            return;
        }
    };
    // Strict arrival order: while anything waits, a new request queues behind it.
    let outcome = match pending.front() {
        Some(front) => SampleOutcome::Blocked(front.blocked),
        None => ctx.lock().try_sample(&request),
    };
    match outcome {
        SampleOutcome::Batch(batch) => reply(&query, &SampleReply::Batch(batch)).await,
        SampleOutcome::Refused(reason) => refuse(&query, request.request_id, reason, 0).await,
        SampleOutcome::Blocked(blocked) => {
            if let Err(query) = pending.push(query, request, blocked, now) {
                let detail = format!("{} sample requests already waiting ({blocked})", pending.len());
                ctx.lock().count_refusal("queue_full");
                let retry = retry_after_ms(ctx, &blocked);
                refuse(&query, request.request_id, RefusalReason::Other { detail }, retry).await;
            }
        }
    }
}

/// Serves waiting requests from the front while the limiter allows.
async fn serve_pending(ctx: &Ctx, pending: &mut Pending<Query>) {
    while let Some(front) = pending.front() {
        let outcome = ctx.lock().try_sample(&front.request);
        if let SampleOutcome::Blocked(blocked) = outcome {
            pending.set_front_blocked(blocked);
            return;
        }
        let Some(waiter) = pending.pop_front() else { return };
        finish_wait(ctx, &waiter, "");
        match outcome {
            SampleOutcome::Batch(batch) => reply(&waiter.ticket, &SampleReply::Batch(batch)).await,
            SampleOutcome::Refused(reason) => {
                refuse(&waiter.ticket, waiter.request.request_id, reason, 0).await
            }
            SampleOutcome::Blocked(_) => {}
        }
    }
}

/// Refuses the requests whose deadline has passed, with the reason they waited for.
async fn expire(ctx: &Ctx, pending: &mut Pending<Query>) {
    for waiter in pending.expire(Instant::now()) {
        let key = waiter.blocked.key();
        finish_wait(ctx, &waiter, key);
        let retry = retry_after_ms(ctx, &waiter.blocked);
        let reason = waiter.blocked.to_refusal();
        refuse(&waiter.ticket, waiter.request.request_id, reason, retry).await;
    }
}

/// Books the time a request spent blocked and, if it is refused, the refusal under `refused`.
fn finish_wait(ctx: &Ctx, waiter: &Waiter<Query>, refused: &str) {
    let mut service = ctx.lock();
    service.add_blocked_ms(waiter.blocked.key(), waiter.arrived.elapsed().as_millis() as u64);
    if !refused.is_empty() {
        service.count_refusal(refused);
    }
}

fn publish_waiting(ctx: &Ctx, pending: &Pending<Query>) {
    let waiting = pending.front().map(|front| Waiting {
        count: pending.len(),
        since_unix_ms: unix_ms_of(front.arrived),
        why: front.blocked.to_string(),
    });
    ctx.lock().set_waiting(waiting);
}

/// When to ask again: the inserts still missing at the recent insert rate, within [1 ms, deadline].
fn retry_after_ms(ctx: &Ctx, blocked: &Blocked) -> u32 {
    let deadline = ctx.cfg.request_deadline_ms;
    let rate = f64::from_bits(ctx.insert_rate.load(Ordering::Relaxed));
    let ms =
        if rate > 0.0 { (blocked.missing_inserts() as f64 / rate * 1e3).ceil() as u64 } else { deadline };
    ms.clamp(1, deadline) as u32
}

async fn refuse(query: &Query, request_id: u64, reason: RefusalReason, retry_after_ms: u32) {
    reply(query, &SampleReply::Refused(SampleRefusal { request_id, reason, retry_after_ms })).await;
}

/// Sends `message` as `query`'s reply. A querier that timed out or went away is only logged:
/// nothing to undo.
async fn reply<M: proto::Message>(query: &Query, message: &M) {
    if let Err(e) = query.reply(query.key_expr().clone(), proto::encode(message)).express(true).await {
        tracing::debug!(error = %e, kind = %M::KIND, "could not send a reply");
    }
}

pub(crate) async fn state_loop(
    ctx: Arc<Ctx>,
    queries: QueryQueue,
    mut shutdown: Shutdown,
) -> anyhow::Result<()> {
    while let Some(query) = next_query(&queries, &mut shutdown).await {
        let k = query
            .parameters()
            .get("k")
            .and_then(|k| k.parse::<u32>().ok())
            .unwrap_or(ctx.cfg.top_k)
            .min(MAX_TOP_K) as usize;
        let (mut report, digest) =
            scan(&ctx, k, |service, digest| (ctx.report(service, Rates::default(), digest.as_ref()), digest))
                .await;
        // Rates need an interval; the state query is a point in time, so it leaves them out.
        report.metrics.retain(|m| !m.name.ends_with("_per_s"));
        for (rank, entry) in digest.iter().flat_map(|d| d.top.iter()).enumerate() {
            report.push_metric(format!("replay/top.{rank}.priority"), entry.priority);
            report.push_metric(format!("replay/top.{rank}.slot"), entry.id.slot as f64);
            report.push_metric(format!("replay/top.{rank}.generation"), entry.id.generation as f64);
        }
        reply(&query, &report).await;
    }
    Ok(())
}

/// Answers `replay/cut`: where a deterministic run resumes (`None` in normal mode).
pub(crate) async fn cut_loop(
    ctx: Arc<Ctx>,
    queries: QueryQueue,
    mut shutdown: Shutdown,
) -> anyhow::Result<()> {
    while let Some(query) = next_query(&queries, &mut shutdown).await {
        let cut = proto::ReplayCut {
            lockstep: ctx.lock().lockstep().map(|l| proto::CutState {
                learner_step: l.last_cut(),
                cuts: l.cuts(),
                progress: l.progress().to_vec(),
            }),
        };
        reply(&query, &cut).await;
    }
    Ok(())
}

/// The next query, or `None` once shutdown fires or the queryable closes.
async fn next_query(queries: &QueryQueue, shutdown: &mut Shutdown) -> Option<Query> {
    tokio::select! {
        biased;
        _ = shutdown.wait() => None,
        received = queries.recv() => received.ok(),
    }
}
