//! `bus-rogue [bus options] --seconds S`: a peer that attacks a run, for the network-namespace test of
//! authenticated runs. For S seconds it publishes what only other roles may publish (weights to the
//! param server and as the param server's push, a learner step of 2^62, experience, barrier
//! reports, durable marks, a liveliness token of a ghost executor), asks the replay server for
//! samples, and asks the param server for weights (what a monitor may do, so that a rogue holding a
//! monitor's certificate shows it did reach the run), going on past S seconds until one weights
//! reply has come or `--max-seconds` have passed. A session the param server has not answered at all
//! (neither weights nor an error) after `REOPEN_AFTER` is closed and opened afresh, logged with the
//! peers it had: a safety net, since in one CI run a rogue that also listened heard nothing from the
//! param server for 60 s (cause not confirmed).
//! At the end it prints one line:
//! `bus-rogue: weights_replies=N weights_errors=E sample_replies=M puts=K sessions=S peers=P` (E: error
//! replies, the param server's before it holds weights; P: the last session's peers, so a rogue that
//! reached nothing says so).

use std::time::{Duration, Instant};

use clap::Parser;
use node::{BusConfig, NodeArgs};
use proto::{LearnerStep, RunId, SampleRequest, WeightsSnapshot, topics};

/// A forged version and step: far beyond anything a run of the test reaches.
const FORGED: u64 = 1 << 40;

#[derive(Debug, Parser)]
#[command(name = "bus-rogue")]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// How long to attack.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Past `seconds`, go on until one weights reply has come or this many seconds have passed (a
    /// rogue started beside the run may begin before the param server holds weights).
    #[arg(long, default_value_t = 30.0)]
    max_seconds: f64,
}

/// How long a session may go unanswered by the param server before it is closed and opened afresh.
const REOPEN_AFTER: Duration = Duration::from_secs(10);

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    node::telemetry::init();
    let args = Args::parse();
    let run = RunId::new(args.node.run_id.clone())?;
    let config = BusConfig::from(&args.node);
    let weights = proto::encode(&WeightsSnapshot {
        version: FORGED,
        learner_step: FORGED,
        safetensors: b"not a safetensors file".to_vec(),
        stack: None,
    });
    let step = proto::encode(&LearnerStep { learner_step: 1 << 62, weights_version: FORGED, starved: true });
    let sample = proto::encode(&SampleRequest { request_id: 1, learner_step: FORGED, batch_size: 32 });
    let garbage = b"forged by bus-rogue".to_vec();
    let puts: [(String, &Vec<u8>); 8] = [
        (topics::params_publish(&run), &weights),
        (proto::Topic::ParamsStream.key(&run), &weights),
        (topics::params_weights(&run), &weights),
        (topics::control_learner(&run), &step),
        (topics::experience(&run, 7), &garbage),
        (topics::control_barrier(&run, 7), &garbage),
        (topics::replay_durable(&run), &garbage),
        (topics::episodes(&run, 7), &garbage),
    ];
    let (mut weights_replies, mut weights_errors, mut sample_replies) = (0u64, 0u64, 0u64);
    let (mut sent, mut sessions) = (0u64, 1u64);
    let mut rogue = Rogue::open(&config, &run).await?;
    let start = Instant::now();
    let (min, max) = (Duration::from_secs_f64(args.seconds), Duration::from_secs_f64(args.max_seconds));
    while start.elapsed() < min || (weights_replies == 0 && start.elapsed() < max) {
        for (key, payload) in &puts {
            if rogue.session.put(key, (*payload).clone()).await.is_ok() {
                sent += 1;
            }
        }
        sample_replies +=
            answered(&rogue.session, &topics::replay_sample(&run), Some(sample.clone())).await.ok;
        let weights = answered(&rogue.session, &topics::params_weights(&run), None).await;
        (weights_replies, weights_errors) = (weights_replies + weights.ok, weights_errors + weights.err);
        rogue.heard_param |= weights.ok + weights.err > 0;
        if rogue.unanswered_past(REOPEN_AFTER) && start.elapsed() + REOPEN_AFTER < max {
            tracing::warn!(
                peers = rogue.peers().await,
                "no reply from the param server yet; opening the session afresh"
            );
            rogue.session.close().await.map_err(anyhow::Error::msg)?;
            rogue = Rogue::open(&config, &run).await?;
            sessions += 1;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let peers = rogue.peers().await;
    println!(
        "bus-rogue: weights_replies={weights_replies} weights_errors={weights_errors} \
         sample_replies={sample_replies} puts={sent} sessions={sessions} peers={peers}"
    );
    rogue.session.close().await.map_err(anyhow::Error::msg)?;
    Ok(())
}

/// One session of the rogue, with the liveliness token of a ghost executor declared on it.
struct Rogue {
    session: zenoh::Session,
    _token: zenoh::liveliness::LivelinessToken,
    opened: Instant,
    /// Whether the param server has answered this session (weights or an error) at least once.
    heard_param: bool,
}

impl Rogue {
    async fn open(config: &BusConfig, run: &RunId) -> anyhow::Result<Self> {
        let session = zenoh::open(config.to_zenoh()?).await.map_err(anyhow::Error::msg)?;
        let ghost = proto::NodeId { role: proto::Role::Executor, id: 7 };
        let _token = session
            .liveliness()
            .declare_token(topics::liveliness(run, ghost))
            .await
            .map_err(anyhow::Error::msg)?;
        Ok(Self { session, _token, opened: Instant::now(), heard_param: false })
    }

    /// Whether the param server has not answered this session in `limit` since it opened.
    fn unanswered_past(&self, limit: Duration) -> bool {
        !self.heard_param && self.opened.elapsed() > limit
    }

    /// How many peers the session is connected to.
    async fn peers(&self) -> usize {
        self.session.info().peers_zid().await.count()
    }
}

/// The replies to one query, counted by kind.
#[derive(Debug, Default)]
struct Replies {
    /// Successful replies.
    ok: u64,
    /// Error replies (the param server's before it holds weights).
    err: u64,
}

/// The replies to one query, waiting at most 300 ms.
async fn answered(session: &zenoh::Session, key: &str, payload: Option<Vec<u8>>) -> Replies {
    // As the roles ask (node::Bus::query_with): replies count when they arrive, not only once every
    // peer the query went to has finished.
    let mut get = session
        .get(key)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_millis(300));
    if let Some(payload) = payload {
        get = get.payload(payload);
    }
    let mut replies = Replies::default();
    let Ok(receiver) = get.await else { return replies };
    while let Ok(reply) = receiver.recv_async().await {
        if reply.result().is_ok() {
            replies.ok += 1;
        } else {
            replies.err += 1;
        }
    }
    replies
}
