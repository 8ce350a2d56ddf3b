//! `bus-rogue [bus options] --seconds S`: a peer that attacks a run, for the network-namespace test of
//! authenticated runs. For S seconds it publishes what only other roles may publish (weights to the
//! param server and as the param server's push, a learner step of 2^62, experience, barrier
//! reports, durable marks, a liveliness token of a ghost executor), asks the replay server for
//! samples, and asks the param server for weights (what a monitor may do, so that a rogue holding a
//! monitor's certificate shows it did reach the run), going on past S seconds until one weights
//! reply has come or `--max-seconds` have passed.
//! At the end it prints one line: `bus-rogue: weights_replies=N sample_replies=M puts=K`.

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

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let run = RunId::new(args.node.run_id.clone())?;
    let session = zenoh::open(BusConfig::from(&args.node).to_zenoh()?).await.map_err(anyhow::Error::msg)?;
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
    let ghost = proto::NodeId { role: proto::Role::Executor, id: 7 };
    let _token = session
        .liveliness()
        .declare_token(topics::liveliness(&run, ghost))
        .await
        .map_err(anyhow::Error::msg)?;
    let (mut weights_replies, mut sample_replies, mut sent) = (0u64, 0u64, 0u64);
    let start = Instant::now();
    let (min, max) = (Duration::from_secs_f64(args.seconds), Duration::from_secs_f64(args.max_seconds));
    while start.elapsed() < min || (weights_replies == 0 && start.elapsed() < max) {
        for (key, payload) in &puts {
            if session.put(key, (*payload).clone()).await.is_ok() {
                sent += 1;
            }
        }
        sample_replies += answered(&session, &topics::replay_sample(&run), Some(sample.clone())).await;
        weights_replies += answered(&session, &topics::params_weights(&run), None).await;
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    println!("bus-rogue: weights_replies={weights_replies} sample_replies={sample_replies} puts={sent}");
    session.close().await.map_err(anyhow::Error::msg)?;
    Ok(())
}

/// The number of successful replies to one query, waiting at most 300 ms.
async fn answered(session: &zenoh::Session, key: &str, payload: Option<Vec<u8>>) -> u64 {
    // As the roles ask (node::Bus::query_with): replies count when they arrive, not only once every
    // peer the query went to has finished.
    let mut get = session
        .get(key)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_millis(300));
    if let Some(payload) = payload {
        get = get.payload(payload);
    }
    let Ok(replies) = get.await else { return 0 };
    let mut n = 0;
    while let Ok(reply) = replies.recv_async().await {
        n += u64::from(reply.result().is_ok());
    }
    n
}
