//! The zenoh session of one process, scoped to a run.

use std::time::Duration;

use proto::{DecodeError, Message, NodeId, Role, RunId, Topic, TopicSet};
use zenoh::bytes::ZBytes;
use zenoh::handlers::FifoChannel;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::query::ConsolidationMode;

use crate::endpoints::{Delivery, Publisher, Queryable, Subscriber, let_out};
use crate::faults::Faults;
use crate::{BusConfig, NodeError};

/// Messages a subscriber or queryable holds before zenoh drops (zenoh's own default).
pub const DEFAULT_QUEUE: usize = 256;

/// A process's connection to the bus: a zenoh session, the run it belongs to, and who it is.
/// Cloning shares the session.
///
/// Roles declare their endpoints through the typed methods ([`Bus::publisher`], [`Bus::subscribe`],
/// [`Bus::queryable`], [`Bus::query`], [`Bus::put`]), keyed by [`proto`] topics, so that every message
/// passes through the process's [`Faults`]: tests drop, delay or cut messages per topic there.
#[derive(Clone)]
pub struct Bus {
    session: zenoh::Session,
    run: RunId,
    node: NodeId,
    faults: Faults,
}

impl std::fmt::Debug for Bus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bus").field("run", &self.run.as_str()).field("node", &self.node).finish()
    }
}

impl Bus {
    /// Opens a session for `node` in run `run`.
    pub async fn open(run: RunId, node: NodeId, config: &BusConfig) -> Result<Self, NodeError> {
        let session = zenoh::open(config.to_zenoh()?).await.map_err(NodeError::zenoh)?;
        Ok(Self { session, run, node, faults: Faults::default() })
    }

    /// The zenoh session itself, for what is not a run topic (and for tools that watch a whole run);
    /// roles use the typed methods.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// This process's fault rules (empty unless a test installs some); clones share them.
    pub fn faults(&self) -> &Faults {
        &self.faults
    }

    /// This bus with `faults` as its rules (a test harness keeps one set per process across restarts).
    pub fn with_faults(mut self, faults: Faults) -> Bus {
        self.faults = faults;
        self
    }

    /// The run this process belongs to.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// This process's role and id.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// Encodes and publishes one message on `topic`. Blocks (never drops) under congestion:
    /// transitions and weights must not be lost silently.
    pub async fn put<M: Message>(&self, topic: Topic, message: &M) -> Result<(), NodeError> {
        if !let_out(&self.faults, topic).await {
            return Ok(());
        }
        self.session
            .put(topic.key(&self.run), proto::encode(message))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(NodeError::zenoh)
    }

    /// Publishes this process's stats on `stats/<role>/<id>`. Dropped rather than blocking under
    /// congestion: the next report supersedes it.
    pub async fn put_stats(&self, report: &proto::StatsReport) -> Result<(), NodeError> {
        let topic = Topic::Stats(self.node);
        if !let_out(&self.faults, topic).await {
            return Ok(());
        }
        self.session.put(topic.key(&self.run), proto::encode(report)).await.map_err(NodeError::zenoh)
    }

    /// Declares a publisher of `topic`.
    pub async fn publisher(&self, topic: Topic, delivery: Delivery) -> Result<Publisher, NodeError> {
        let declare = self.session.declare_publisher(topic.key(&self.run));
        let inner = match delivery {
            Delivery::Block => declare.congestion_control(CongestionControl::Block).await,
            Delivery::Express => declare.express(true).await,
        };
        Ok(Publisher::new(inner.map_err(NodeError::zenoh)?, topic, self.faults.clone()))
    }

    /// Subscribes to `topics`, holding up to `queue` received messages.
    pub async fn subscribe(
        &self,
        topics: impl Into<TopicSet>,
        queue: usize,
    ) -> Result<Subscriber, NodeError> {
        let inner = self
            .session
            .declare_subscriber(topics.into().key(&self.run))
            .with(FifoChannel::new(queue))
            .await
            .map_err(NodeError::zenoh)?;
        Ok(Subscriber::new(inner, self.faults.clone(), self.run.clone()))
    }

    /// Watches the liveliness tokens of every process in `role`: a put when one appears (those alive
    /// now are delivered at once), a delete when it goes.
    pub async fn watch(&self, role: Role) -> Result<Subscriber, NodeError> {
        let inner = self
            .session
            .liveliness()
            .declare_subscriber(TopicSet::Liveliness(role).key(&self.run))
            .history(true)
            .await
            .map_err(NodeError::zenoh)?;
        Ok(Subscriber::new(inner, self.faults.clone(), self.run.clone()))
    }

    /// Declares a queryable of `topic`, holding up to `queue` queries.
    pub async fn queryable(&self, topic: Topic, queue: usize) -> Result<Queryable, NodeError> {
        let inner = self
            .session
            .declare_queryable(topic.key(&self.run))
            .with(FifoChannel::new(queue))
            .await
            .map_err(NodeError::zenoh)?;
        Ok(Queryable::new(inner, self.faults.clone(), self.run.clone()))
    }

    /// Asks `topic`'s queryable, waiting at most `timeout`: its first answer (the payload, or the
    /// error it replied), `None` if nobody answered in time. Express: a query is small and waited on.
    pub async fn query(
        &self,
        topic: Topic,
        payload: Option<Vec<u8>>,
        timeout: Duration,
    ) -> Result<Option<Result<ZBytes, String>>, NodeError> {
        self.query_with(topic, "", payload, timeout).await
    }

    /// [`Bus::query`] with selector `parameters` (`name=value;...`; empty for none).
    pub async fn query_with(
        &self,
        topic: Topic,
        parameters: &str,
        payload: Option<Vec<u8>>,
        timeout: Duration,
    ) -> Result<Option<Result<ZBytes, String>>, NodeError> {
        if !let_out(&self.faults, topic).await {
            // A lost query is answered by silence, after its timeout.
            tokio::time::sleep(timeout).await;
            return Ok(None);
        }
        let key = topic.key(&self.run);
        let selector = if parameters.is_empty() { key } else { format!("{key}?{parameters}") };
        // No consolidation: the first reply is delivered when it arrives. The default holds replies
        // until every peer the query went to has finished, so one peer that never finishes (seen
        // with access control, a query sent to another executor too) withheld the param server's
        // answer until the timeout, every time.
        let mut get =
            self.session.get(selector).express(true).consolidation(ConsolidationMode::None).timeout(timeout);
        if let Some(payload) = payload {
            get = get.payload(payload);
        }
        let replies = get.await.map_err(NodeError::zenoh)?;
        Ok(replies.recv_async().await.ok().map(|reply| match reply.result() {
            Ok(sample) => Ok(sample.payload().clone()),
            Err(error) => Err(String::from_utf8_lossy(&error.payload().to_bytes()).into_owned()),
        }))
    }

    /// Declares this process alive under `liveliness/<role>/<id>` for as long as the token lives; peers
    /// see it vanish when the process dies, however it dies.
    pub async fn announce(&self) -> Result<LivelinessToken, NodeError> {
        let key = proto::topics::liveliness(&self.run, self.node);
        self.session.liveliness().declare_token(key).await.map_err(NodeError::zenoh)
    }

    /// Closes the session, flushing what is queued.
    pub async fn close(self) -> Result<(), NodeError> {
        self.session.close().await.map_err(NodeError::zenoh)
    }
}

/// Decodes a received payload as `M`, with the codec's checks (framing, checksum, kind, contents).
pub fn decode_payload<M: Message>(payload: &ZBytes) -> Result<M, DecodeError> {
    proto::decode(&payload.to_bytes())
}
