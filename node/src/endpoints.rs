//! The bus's typed endpoints: a publisher of one topic, a subscriber or queryable of a topic set, each
//! passing its messages through the process's [`Faults`] (a no-op outside tests).

use std::collections::VecDeque;
use std::future::Future;
use std::sync::{Mutex, PoisonError};

use proto::{RunId, Topic};
use tokio::time::Instant;
use zenoh::bytes::ZBytes;
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::Query;
use zenoh::sample::Sample;

use crate::NodeError;
use crate::faults::{Direction, Faults, Verdict};

/// How a publisher behaves under congestion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Wait for room rather than drop: experience and weights must not be lost silently.
    Block,
    /// Sent at once, unbatched, dropped under congestion: small, frequent announcements that the next
    /// one supersedes.
    Express,
}

/// Applies the faults of incoming messages: drops, and holds delayed messages in arrival order, each
/// until its due time, taking in new arrivals while it waits (a delay is a slow link, not a narrow
/// one); held messages are kept across a receive cancelled while it waits (a `select!` arm losing).
struct Gate<T> {
    faults: Faults,
    run: RunId,
    held: Mutex<VecDeque<(Instant, T)>>,
}

/// A received message's key.
pub trait Keyed {
    /// The key it arrived on.
    fn key(&self) -> &str;
}

impl Keyed for Sample {
    fn key(&self) -> &str {
        self.key_expr().as_str()
    }
}

impl Keyed for Query {
    fn key(&self) -> &str {
        self.key_expr().as_str()
    }
}

impl<T: Keyed> Gate<T> {
    fn new(faults: Faults, run: RunId) -> Self {
        Self { faults, run, held: Mutex::new(VecDeque::new()) }
    }

    fn held(&self) -> std::sync::MutexGuard<'_, VecDeque<(Instant, T)>> {
        self.held.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The next message `recv` yields that the faults let through, when they let it through.
    async fn next<F, E>(&self, mut recv: impl FnMut() -> F) -> Result<T, NodeError>
    where
        F: Future<Output = Result<T, E>>,
        E: std::fmt::Display,
    {
        loop {
            let due = self.held().front().map(|(due, _)| *due);
            let received = match due {
                Some(due) => tokio::select! {
                    biased;
                    _ = tokio::time::sleep_until(due) => match self.held().pop_front() {
                        Some((_, message)) => return Ok(message),
                        None => continue,
                    },
                    received = recv() => received,
                },
                None => recv().await,
            };
            let message = received.map_err(|e| NodeError::Zenoh(format!("receiving: {e}")))?;
            let now = Instant::now();
            match self.faults.verdict(Direction::In, || Topic::parse(&self.run, message.key()).ok()) {
                Verdict::Pass if self.held().is_empty() => return Ok(message),
                // Behind the held ones: a link keeps order.
                Verdict::Pass => self.held().push_back((now, message)),
                Verdict::Drop => continue,
                Verdict::Delay(by) => self.held().push_back((now + by, message)),
            }
        }
    }
}

/// Whether an outgoing message on `topic` goes now (after any delay a rule asks for), or is lost.
pub(crate) async fn let_out(faults: &Faults, topic: Topic) -> bool {
    match faults.verdict(Direction::Out, || Some(topic)) {
        Verdict::Pass => true,
        Verdict::Drop => false,
        Verdict::Delay(by) => {
            tokio::time::sleep(by).await;
            true
        }
    }
}

/// A publisher of one topic.
pub struct Publisher {
    inner: zenoh::pubsub::Publisher<'static>,
    topic: Topic,
    faults: Faults,
}

impl std::fmt::Debug for Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publisher").field("topic", &self.topic).finish()
    }
}

impl Publisher {
    pub(crate) fn new(inner: zenoh::pubsub::Publisher<'static>, topic: Topic, faults: Faults) -> Self {
        Self { inner, topic, faults }
    }

    /// Publishes an encoded frame.
    pub async fn put(&self, frame: impl Into<ZBytes>) -> Result<(), NodeError> {
        if !let_out(&self.faults, self.topic).await {
            return Ok(());
        }
        self.inner.put(frame).await.map_err(NodeError::zenoh)
    }

    /// Encodes and publishes one message.
    pub async fn put_message<M: proto::Message>(&self, message: &M) -> Result<(), NodeError> {
        self.put(proto::encode(message)).await
    }

    /// A listener told whenever subscribers appear or all go (e.g. a param server starting).
    pub async fn matching_listener(
        &self,
    ) -> Result<
        zenoh::matching::MatchingListener<FifoChannelHandler<zenoh::matching::MatchingStatus>>,
        NodeError,
    > {
        self.inner.matching_listener().await.map_err(NodeError::zenoh)
    }
}

/// Messages of type `T` arriving on a zenoh declaration `D` (a subscriber or a queryable, kept
/// declared while this lives), each passing the process's faults.
pub struct Incoming<D, T> {
    inner: D,
    gate: Gate<T>,
}

/// A subscriber of a topic set (or of liveliness tokens).
pub type Subscriber = Incoming<zenoh::pubsub::Subscriber<FifoChannelHandler<Sample>>, Sample>;

/// A queryable of one topic.
pub type Queryable = Incoming<zenoh::query::Queryable<FifoChannelHandler<Query>>, Query>;

impl<D, T> std::fmt::Debug for Incoming<D, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Incoming").field("of", &std::any::type_name::<T>()).finish()
    }
}

impl<D, T> Incoming<D, T>
where
    D: std::ops::Deref<Target = FifoChannelHandler<T>>,
    T: Keyed + Send + 'static,
{
    pub(crate) fn new(inner: D, faults: Faults, run: RunId) -> Self {
        Self { inner, gate: Gate::new(faults, run) }
    }

    /// The next message; an error once the declaration is closed. Cancel-safe.
    pub async fn recv(&self) -> Result<T, NodeError> {
        self.gate.next(|| self.inner.recv_async()).await
    }
}
