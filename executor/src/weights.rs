//! The weights fetch task: whenever an announcement names a newer version than the one held (or
//! none is held yet), one `get` on the param server's queryable, retried every 500 ms while it
//! fails; the result goes straight into the rollout thread's inbox. In deterministic mode it
//! fetches instead the exact version the rollout thread says its next steps need
//! (`params/weights?version=V`), once it is announced.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent::ParamSnapshot;
use node::{Bus, Rejects, Shutdown};
use proto::{ContentHash, Topic, WeightsSnapshot};
use tokio::sync::watch;

use crate::inbox::Inbox;

/// Wait between attempts while fetching fails (weights and frozen levels).
pub(crate) const RETRY: Duration = Duration::from_millis(500);

/// What the task needs.
pub(crate) struct Fetch {
    pub bus: Bus,
    /// The newest weights version announced on `control/step`.
    pub announced: watch::Receiver<Option<u64>>,
    /// Deterministic mode: the exact version the rollout thread wants next.
    pub exact: Option<watch::Receiver<Option<u64>>>,
    pub inbox: Arc<Inbox>,
    pub timeout: Duration,
    /// The frozen levels' hash every snapshot must carry (`None`: a single-level run).
    pub stack: Option<ContentHash>,
    pub rejects: Arc<Mutex<Rejects>>,
    pub shutdown: Shutdown,
}

/// Runs until shutdown (or the shell drops the announcement channel); returns the snapshots fetched.
pub(crate) async fn fetch_loop(mut f: Fetch) -> u64 {
    if let Some(exact) = f.exact.take() {
        return fetch_exact_loop(f, exact).await;
    }
    let mut held: Option<u64> = None;
    let mut fetched = 0;
    loop {
        let wanted = match (*f.announced.borrow(), held) {
            (_, None) => true,
            (Some(version), Some(have)) => version > have,
            (None, Some(_)) => false,
        };
        if wanted {
            let fetch = fetch_weights(&f.bus, "", f.timeout).await;
            if let Some(version) = f.accept(fetch, |v| held.is_none_or(|have| v > have)) {
                held = Some(version);
                fetched += 1;
                continue;
            }
        }
        tokio::select! {
            _ = f.shutdown.wait() => return fetched,
            changed = f.announced.changed() => if changed.is_err() { return fetched },
            _ = tokio::time::sleep(RETRY), if wanted => {}
        }
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
