//! The weights fetch task: whenever an announcement names a newer version than the one held (or
//! none is held yet), one `get` on the param server's queryable, retried every 500 ms while it
//! fails; the result goes straight into the rollout thread's inbox.

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
    pub inbox: Arc<Inbox>,
    pub timeout: Duration,
    /// The frozen levels' hash every snapshot must carry (`None`: a single-level run).
    pub stack: Option<ContentHash>,
    pub rejects: Arc<Mutex<Rejects>>,
    pub shutdown: Shutdown,
}

/// Runs until shutdown (or the shell drops the announcement channel); returns the snapshots fetched.
pub(crate) async fn fetch_loop(mut f: Fetch) -> u64 {
    let mut held: Option<u64> = None;
    let mut fetched = 0;
    loop {
        let wanted = match (*f.announced.borrow(), held) {
            (_, None) => true,
            (Some(version), Some(have)) => version > have,
            (None, Some(_)) => false,
        };
        if wanted {
            match fetch_weights(&f.bus, f.timeout).await {
                Ok(Some(snapshot)) if let Some(detail) = snapshot.stack_mismatch(f.stack) => {
                    let now = std::time::Instant::now();
                    crate::lock(&f.rejects).record("weights/stack_mismatch", &detail, now);
                }
                Ok(Some(snapshot)) if held.is_none_or(|have| snapshot.version > have) => {
                    held = Some(snapshot.version);
                    fetched += 1;
                    let WeightsSnapshot { version, safetensors, .. } = snapshot;
                    f.inbox.set_weights(ParamSnapshot { version, safetensors });
                    continue;
                }
                Ok(_) => {}
                Err(FetchError::Decode(error)) => crate::lock(&f.rejects).decode_failed("weights", &error),
                Err(FetchError::Unavailable(why)) => tracing::debug!(%why, "weights not available yet"),
            }
        }
        tokio::select! {
            _ = f.shutdown.wait() => return fetched,
            changed = f.announced.changed() => if changed.is_err() { return fetched },
            _ = tokio::time::sleep(RETRY), if wanted => {}
        }
    }
}

/// Why a query got no message.
pub(crate) enum FetchError {
    Decode(proto::DecodeError),
    Unavailable(String),
}

/// One `get` of the latest weights.
async fn fetch_weights(bus: &Bus, timeout: Duration) -> Result<Option<WeightsSnapshot>, FetchError> {
    query(bus, Topic::ParamsWeights, timeout).await
}

/// One `get` on a param-server queryable: its first reply decoded, `None` if nobody replied.
pub(crate) async fn query<M: proto::Message>(
    bus: &Bus,
    topic: Topic,
    timeout: Duration,
) -> Result<Option<M>, FetchError> {
    match bus.query(topic, None, timeout).await.map_err(|e| FetchError::Unavailable(e.to_string()))? {
        Some(Ok(payload)) => proto::decode(&payload.to_bytes()).map(Some).map_err(FetchError::Decode),
        Some(Err(error)) => Err(FetchError::Unavailable(error)),
        None => Ok(None),
    }
}
