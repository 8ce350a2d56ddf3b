//! The weights task. New versions normally arrive by the param server's push (`params/stream`, each
//! version once, fanned out by the zenoh routers); the param server's queryable (one `get`, retried
//! every 500 ms while it fails) serves what no push brought: the weights a joiner starts from, and a
//! version whose push has not come within [`PUSH_GRACE`] of its announcement (every version, when
//! the push is off). Which to take and when to ask: [`crate::push::PushTracker`]. In deterministic
//! mode it asks instead for the exact version the rollout thread says its next steps need
//! (`params/weights?version=V`), once it is announced. What it takes goes straight into the rollout
//! thread's inbox.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::ParamSnapshot;
use node::{Bus, NodeError, Rejects, Shutdown, Subscriber};
use proto::{ContentHash, Topic, WeightsSnapshot};
use tokio::sync::watch;
use tokio::time::Instant;
use zenoh::sample::Sample;

use crate::inbox::Inbox;
use crate::push::PushTracker;

/// Wait between attempts while fetching fails (weights and frozen levels).
pub(crate) const RETRY: Duration = Duration::from_millis(500);

/// How long an announced version may take to arrive by push before it is asked for. The param
/// server pushes a version before announcing it, so on a working link the push is there first or
/// within its transfer time (well under a second for the Ant's networks on a slow link); a push
/// lost to congestion or a partition costs this much lag, once.
pub const PUSH_GRACE: Duration = Duration::from_secs(1);

/// Weights queues at most this many pushed frames; the task takes them as they come.
pub(crate) const PUSH_QUEUE: usize = 4;

/// What the task needs.
pub(crate) struct Fetch {
    pub bus: Bus,
    /// The newest weights version announced on `control/step`.
    pub announced: watch::Receiver<Option<u64>>,
    /// Deterministic mode: the exact version the rollout thread wants next.
    pub exact: Option<watch::Receiver<Option<u64>>>,
    /// The param server's push (`params/stream`), when `[executor] weights_push`.
    pub pushed: Option<Subscriber>,
    pub inbox: Arc<Inbox>,
    pub timeout: Duration,
    /// The frozen levels' hash every snapshot must carry (`None`: a single-level run).
    pub stack: Option<ContentHash>,
    pub rejects: Arc<Mutex<Rejects>>,
    pub shutdown: Shutdown,
}

/// How the task got the versions it handed on.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct WeightsTaken {
    /// Versions taken from a query's reply.
    pub asked: u64,
    /// Versions taken from the push.
    pub pushed: u64,
}

/// Runs until shutdown (or the shell drops the announcement channel); returns what it took.
pub(crate) async fn fetch_loop(mut f: Fetch) -> WeightsTaken {
    if let Some(exact) = f.exact.take() {
        return WeightsTaken { asked: fetch_exact_loop(f, exact).await, pushed: 0 };
    }
    let mut push = f.pushed.take();
    let mut tracker = PushTracker::new(push.is_some(), PUSH_GRACE, RETRY);
    let mut taken = WeightsTaken::default();
    loop {
        let newest = *f.announced.borrow_and_update();
        if let Some(frame) = tracker.announced(newest, Instant::now()) {
            f.take_pushed(frame, &mut tracker, &mut taken);
        }
        if tracker.ask_due(Instant::now()) {
            let fetch = fetch_weights(&f.bus, "", f.timeout).await;
            match f.accept(fetch, |v| tracker.wants(v)) {
                Some(version) => {
                    tracker.took(version, Instant::now());
                    taken.asked += 1;
                }
                None => tracker.ask_failed(Instant::now()),
            }
            continue;
        }
        let ask_at = tracker.ask_at();
        tokio::select! {
            _ = f.shutdown.wait() => return taken,
            changed = f.announced.changed() => if changed.is_err() { return taken },
            received = next_push(push.as_ref()) => match received {
                Ok(sample) => match proto::decode::<WeightsSnapshot>(&sample.payload().to_bytes()) {
                    Ok(frame) => if let Some(frame) = tracker.pushed(frame, Instant::now()) {
                        f.take_pushed(frame, &mut tracker, &mut taken);
                    },
                    Err(error) => crate::lock(&f.rejects).decode_failed("weights_push", &error),
                },
                Err(error) => {
                    tracing::warn!(%error, "the weights push closed; asking for every version from now on");
                    push = None;
                    tracker.push_closed(Instant::now());
                }
            },
            _ = tokio::time::sleep_until(ask_at.unwrap_or_else(Instant::now)), if ask_at.is_some() => {}
        }
    }
}

/// The next pushed frame; never, without a push.
async fn next_push(push: Option<&Subscriber>) -> Result<Sample, NodeError> {
    match push {
        Some(push) => push.recv().await,
        None => std::future::pending().await,
    }
}

/// Deterministic mode's loop: fetches the version in `exact` once an announcement says it exists.
async fn fetch_exact_loop(mut f: Fetch, mut exact: watch::Receiver<Option<u64>>) -> u64 {
    let mut held: Option<u64> = None;
    let mut fetched = 0;
    loop {
        let want = *exact.borrow_and_update();
        let newest = *f.announced.borrow_and_update();
        let due = want.filter(|&w| held != Some(w) && newest.is_some_and(|n| n >= w));
        if let Some(want) = due {
            let parameters = format!("{}={want}", proto::topics::WEIGHTS_VERSION_PARAMETER);
            let reply = fetch_weights(&f.bus, &parameters, f.timeout).await;
            if f.accept(reply, |v| v == want).is_some() {
                held = Some(want);
                fetched += 1;
                continue;
            }
        }
        tokio::select! {
            _ = f.shutdown.wait() => return fetched,
            changed = f.announced.changed() => if changed.is_err() { return fetched },
            changed = exact.changed() => if changed.is_err() { return fetched },
            _ = tokio::time::sleep(RETRY), if due.is_some() => {}
        }
    }
}

impl Fetch {
    /// Hands on a pushed frame the tracker released.
    fn take_pushed(&self, frame: WeightsSnapshot, tracker: &mut PushTracker, taken: &mut WeightsTaken) {
        if let Some(version) = self.accept(Ok(Some(frame)), |v| tracker.wants(v)) {
            tracker.took(version, Instant::now());
            taken.pushed += 1;
        }
    }

    /// Hands a fetched snapshot whose version `takes` to the inbox and returns its version; counts
    /// what cannot be used.
    fn accept(
        &self,
        fetched: Result<Option<WeightsSnapshot>, FetchError>,
        takes: impl Fn(u64) -> bool,
    ) -> Option<u64> {
        match fetched {
            Ok(Some(snapshot)) if let Some(detail) = snapshot.stack_mismatch(self.stack) => {
                let now = std::time::Instant::now();
                crate::lock(&self.rejects).record("weights/stack_mismatch", &detail, now);
            }
            Ok(Some(snapshot)) if takes(snapshot.version) => {
                let WeightsSnapshot { version, safetensors, .. } = snapshot;
                self.inbox.set_weights(ParamSnapshot { version, safetensors });
                return Some(version);
            }
            Ok(_) => {}
            Err(FetchError::Decode(error)) => crate::lock(&self.rejects).decode_failed("weights", &error),
            Err(FetchError::Unavailable(why)) => tracing::debug!(%why, "weights not available yet"),
        }
        None
    }
}

/// Why a query got no message.
pub(crate) enum FetchError {
    Decode(proto::DecodeError),
    Unavailable(String),
}

/// One `get` of the weights: the newest, or those the selector `parameters` name.
async fn fetch_weights(
    bus: &Bus,
    parameters: &str,
    timeout: Duration,
) -> Result<Option<WeightsSnapshot>, FetchError> {
    query_with(bus, Topic::ParamsWeights, parameters, timeout).await
}

/// One `get` on a param-server queryable: its first reply decoded, `None` if nobody replied.
pub(crate) async fn query<M: proto::Message>(
    bus: &Bus,
    topic: Topic,
    timeout: Duration,
) -> Result<Option<M>, FetchError> {
    query_with(bus, topic, "", timeout).await
}

/// [`query`] with selector parameters.
async fn query_with<M: proto::Message>(
    bus: &Bus,
    topic: Topic,
    parameters: &str,
    timeout: Duration,
) -> Result<Option<M>, FetchError> {
    let asked = bus.query_with(topic, parameters, None, timeout).await;
    match asked.map_err(|e| FetchError::Unavailable(e.to_string()))? {
        Some(Ok(payload)) => proto::decode(&payload.to_bytes()).map(Some).map_err(FetchError::Decode),
        Some(Err(error)) => Err(FetchError::Unavailable(error)),
        None => Ok(None),
    }
}
