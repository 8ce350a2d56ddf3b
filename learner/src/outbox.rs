//! Where the update thread's output goes on the bus. The newest weights frame is kept and sent
//! again whenever a param server starts listening (zenoh's matching status), and whenever the param
//! server's announcements still name older weights a second after the newest were sent, or the
//! learner is starved of data meanwhile (the frame may have been lost on the way): otherwise weights published before the param server was reachable, before
//! it restarted, or lost in transit would be missing, and executors waiting for their first weights
//! (with no data, the learner publishes no newer ones) would wait forever.

use std::time::{Duration, Instant};

use node::{Bus, Delivery, NodeError, Publisher};
use proto::{EvalReport, Topic};
use zenoh::bytes::ZBytes;

use crate::{Fetcher, Out, stats};

/// Changes of "does anyone listen for the weights".
pub(crate) type Matching =
    zenoh::matching::MatchingListener<zenoh::handlers::FifoChannelHandler<zenoh::matching::MatchingStatus>>;

/// How long the param server may go on announcing older weights than the newest sent before they
/// are sent again: announcements made before a frame arrives are normal for a few milliseconds.
const RESEND_AFTER: Duration = Duration::from_secs(1);

/// The newest weights frame, kept for re-sending.
struct Latest {
    frame: ZBytes,
    version: u64,
    sent_at: Instant,
    /// Times sent again: logged at info the first time only (a starved learner re-sends every
    /// second), counted in the report.
    resent: u64,
}

/// The learner's publishing side.
pub(crate) struct Outbox {
    bus: Bus,
    weights: Publisher,
    latest_weights: Option<Latest>,
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
        let weights = bus.publisher(Topic::ParamsPublish, Delivery::Block).await?;
        let matching = weights.matching_listener().await?;
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
        let result = match message {
            Out::Priorities(update) => bus.put(Topic::ReplayPriorities, &update).await,
            Out::Step(step) => {
                self.weights_version = step.weights_version;
                bus.put(Topic::ControlLearner, &step).await
            }
            Out::Weights(weights) => {
                let frame = ZBytes::from(proto::encode(&weights));
                let (version, sent_at) = (weights.version, Instant::now());
                self.latest_weights = Some(Latest { frame: frame.clone(), version, sent_at, resent: 0 });
                self.weights.put(frame).await
            }
            Out::Eval(report) => {
                self.evaluations.push(report);
                bus.put(Topic::Evaluation, &report).await
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
        self.send_latest_again("a param server is listening").await;
    }

    /// The param server announced that it holds weights `held`: if that is older than the newest sent
    /// a while ago, the frame was lost on the way; send it again. While the learner is starved of data
    /// the newest are sent again even when `held` equals their version: an announcement cannot tell
    /// "holds version 0" from "holds nothing", and executors waiting for their first weights are what
    /// starves it (the param server ignores a repeat, counted).
    pub async fn on_announcement(&mut self, held: u64, starved: bool) {
        let lost = self.latest_weights.as_ref().is_some_and(|l| {
            (held < l.version || (starved && held == l.version)) && l.sent_at.elapsed() >= RESEND_AFTER
        });
        if lost {
            self.send_latest_again("the param server announces older weights").await;
        }
    }

    async fn send_latest_again(&mut self, why: &str) {
        let Some(latest) = &mut self.latest_weights else { return };
        self.weights_resent += 1;
        latest.sent_at = Instant::now();
        latest.resent += 1;
        if latest.resent == 1 {
            tracing::info!(version = latest.version, why, "weights sent again");
        } else {
            tracing::debug!(version = latest.version, why, times = latest.resent, "weights sent again");
        }
        if let Err(error) = self.weights.put(latest.frame.clone()).await {
            tracing::warn!(%error, "weights not re-sent");
        }
    }
}
