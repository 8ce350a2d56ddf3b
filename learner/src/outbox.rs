//! Where the update thread's output goes on the bus. The newest weights frame is kept and sent
//! again whenever a param server starts listening (zenoh's matching status): weights published
//! before the param server was reachable, or before it restarted, would otherwise be lost, and the
//! executors would wait for their first weights forever.

use node::{Bus, NodeError};
use proto::{EvalReport, topics};
use zenoh::bytes::ZBytes;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;

use crate::{Fetcher, Out, stats};

/// Changes of "does anyone listen for the weights".
pub(crate) type Matching =
    zenoh::matching::MatchingListener<zenoh::handlers::FifoChannelHandler<zenoh::matching::MatchingStatus>>;

/// The learner's publishing side.
pub(crate) struct Outbox {
    bus: Bus,
    weights: Publisher<'static>,
    latest_weights: Option<ZBytes>,
    /// Evaluations seen so far, for the stats and the role's report.
    pub evaluations: Vec<EvalReport>,
    /// The newest weights version published.
    pub weights_version: u64,
    /// Weight frames sent again because a listener appeared.
    pub weights_resent: u64,
}

impl Outbox {
    /// Declares the weights publisher; returns it with the listener of its matching status.
    pub async fn new(bus: Bus) -> Result<(Outbox, Matching), NodeError> {
        let weights = bus
            .session()
            .declare_publisher(topics::params_publish(bus.run()))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(NodeError::zenoh)?;
        let matching = weights.matching_listener().await.map_err(NodeError::zenoh)?;
        let outbox = Outbox {
            bus,
            weights,
            latest_weights: None,
            evaluations: Vec::new(),
            weights_version: 0,
            weights_resent: 0,
        };
        Ok((outbox, matching))
    }

    /// Sends one message of the update thread.
    pub async fn send(&mut self, message: Out, fetcher: &Fetcher) {
        let bus = &self.bus;
        let run = bus.run();
        let result = match message {
            Out::Priorities(update) => bus.put(&topics::replay_priorities(run), &update).await,
            Out::Step(step) => {
                self.weights_version = step.weights_version;
                bus.put(&topics::control_learner(run), &step).await
            }
            Out::Weights(weights) => {
                let frame = ZBytes::from(proto::encode(&weights));
                self.latest_weights = Some(frame.clone());
                self.weights.put(frame).await.map_err(NodeError::zenoh)
            }
            Out::Eval(report) => {
                self.evaluations.push(report);
                bus.put(&topics::evaluation(run), &report).await
            }
            Out::Progress(progress) => {
                let last_eval = self.evaluations.last().copied();
                bus.put_stats(&stats::report(bus.node(), &progress, &fetcher.status(), last_eval)).await
            }
        };
        if let Err(error) = result {
            tracing::warn!(%error, "publish failed");
        }
    }

    /// Someone started listening for the weights: send them the newest.
    pub async fn resend_weights(&mut self) {
        if let Some(frame) = &self.latest_weights {
            self.weights_resent += 1;
            tracing::info!(version = self.weights_version, "a param server is listening: weights sent again");
            if let Err(error) = self.weights.put(frame.clone()).await {
                tracing::warn!(%error, "weights not re-sent");
            }
        }
    }
}
