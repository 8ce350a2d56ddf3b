//! The zenoh session of one process, scoped to a run.

use proto::{DecodeError, Message, NodeId, RunId};
use zenoh::bytes::ZBytes;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;

use crate::{BusConfig, NodeError};

/// A process's connection to the bus: a zenoh session, the run it belongs to, and who it is.
/// Cloning shares the session.
#[derive(Clone)]
pub struct Bus {
    session: zenoh::Session,
    run: RunId,
    node: NodeId,
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
        Ok(Self { session, run, node })
    }

    /// The zenoh session, for declaring publishers, subscribers and queryables.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// The run this process belongs to.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// This process's role and id.
    pub fn node(&self) -> NodeId {
        self.node
    }

    /// Encodes and publishes one message. Blocks (never drops) under congestion: transitions and
    /// weights must not be lost silently.
    pub async fn put<M: Message>(&self, key: &str, message: &M) -> Result<(), NodeError> {
        self.session
            .put(key, proto::encode(message))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(NodeError::zenoh)
    }

    /// Publishes this process's stats on `stats/<role>/<id>`. Dropped rather than blocking under
    /// congestion: the next report supersedes it.
    pub async fn put_stats(&self, report: &proto::StatsReport) -> Result<(), NodeError> {
        self.session
            .put(proto::topics::stats(&self.run, self.node), proto::encode(report))
            .await
            .map_err(NodeError::zenoh)
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
