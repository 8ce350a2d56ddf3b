//! Loopback harness for the replay server: a server `run` in a task on its own session listening on
//! a free 127.0.0.1 port, client sessions connected to it, readiness by liveliness, and typed
//! helpers for the server's keys. Every wait has a deadline.

#![allow(dead_code)] // Each test binary uses a different subset.

use std::future::Future;
use std::time::Duration;

use node::{Bus, BusConfig, Shutdown, ShutdownTrigger};
use proto::{
    ExperienceBatch, NodeId, Role, RunId, SampleReply, SampleRequest, StatsReport, Transitions, topics,
};
use replay_server::{ReplayServerConfig, Report};
use tokio::task::JoinHandle;
use zenoh::qos::CongestionControl;

pub const ANT_OBS: u32 = 105;
pub const ANT_ACT: u32 = 8;
pub const WAIT: Duration = Duration::from_secs(20);

/// Awaits `f` or fails the test after `WAIT`.
pub async fn within<T>(what: &str, f: impl Future<Output = T>) -> T {
    match tokio::time::timeout(WAIT, f).await {
        Ok(value) => value,
        Err(_) => panic!("timed out after {WAIT:?} waiting for {what}"),
    }
}

/// A running server.
pub struct Server {
    pub endpoint: String,
    pub run: RunId,
    pub trigger: ShutdownTrigger,
    pub task: JoinHandle<anyhow::Result<Report>>,
}

impl Server {
    /// Starts `run` for `cfg` on a fresh port; returns once a client sees its liveliness token.
    pub async fn start(run: &str, cfg: ReplayServerConfig) -> (Server, Client) {
        let port = node::free_loopback_port().expect("a free loopback port");
        Self::start_on(run, cfg, port).await
    }

    pub async fn start_on(run: &str, cfg: ReplayServerConfig, port: u16) -> (Server, Client) {
        let run = RunId::new(run).expect("run id");
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let bus_cfg = BusConfig { listen: vec![endpoint.clone()], ..BusConfig::default() };
        let bus =
            Bus::open(run.clone(), NodeId { role: Role::Replay, id: 0 }, &bus_cfg).await.expect("server bus");
        let (trigger, shutdown) = Shutdown::new();
        let task = tokio::spawn(replay_server::run(cfg, bus, shutdown));
        let client = Client::connect(&run, &endpoint).await;
        client.wait_ready().await;
        (Server { endpoint, run, trigger, task }, client)
    }

    /// Fires shutdown and returns the server's report.
    pub async fn stop(self) -> Report {
        self.trigger.fire();
        within("the server to stop", self.task).await.expect("server task").expect("server run")
    }
}

/// A client session (a learner or executor stand-in).
pub struct Client {
    pub bus: Bus,
}

impl Client {
    pub async fn connect(run: &RunId, endpoint: &str) -> Client {
        let cfg = BusConfig { connect: vec![endpoint.to_string()], ..BusConfig::default() };
        let bus =
            Bus::open(run.clone(), NodeId { role: Role::Learner, id: 0 }, &cfg).await.expect("client bus");
        Client { bus }
    }

    /// Waits until the server's liveliness token is visible (it is declared after every input).
    pub async fn wait_ready(&self) {
        let key = topics::liveliness(self.bus.run(), NodeId { role: Role::Replay, id: 0 });
        within("the server's liveliness token", async {
            loop {
                let replies = self.bus.session().liveliness().get(&key).timeout(Duration::from_secs(1)).await;
                if let Ok(replies) = replies
                    && replies.recv_async().await.is_ok()
                {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
        .await;
    }

    /// Publishes raw bytes on an executor's experience key.
    pub async fn put_raw(&self, executor_id: u32, bytes: Vec<u8>) {
        let key = topics::experience(self.bus.run(), executor_id);
        self.bus
            .session()
            .put(key, bytes)
            .congestion_control(CongestionControl::Block)
            .await
            .expect("put experience");
    }

    pub async fn put_batch(&self, batch: &ExperienceBatch) {
        self.put_raw(batch.executor_id, proto::encode(batch)).await;
    }

    /// Sends a sample request and returns the decoded reply (or the error reply's text).
    pub async fn sample_raw(&self, payload: Vec<u8>, timeout: Duration) -> Result<SampleReply, String> {
        let key = topics::replay_sample(self.bus.run());
        let replies = self
            .bus
            .session()
            .get(key)
            .payload(payload)
            .express(true)
            .timeout(timeout)
            .await
            .map_err(|e| e.to_string())?;
        let reply = replies.recv_async().await.map_err(|e| format!("no reply: {e}"))?;
        match reply.result() {
            Ok(sample) => proto::decode(&sample.payload().to_bytes()).map_err(|e| e.to_string()),
            Err(err) => Err(String::from_utf8_lossy(&err.payload().to_bytes()).into_owned()),
        }
    }

    /// A sample request; waits 5 s past the longest deadline the tests configure (10 s), so a
    /// request held to its deadline is answered with its refusal, never taken for silence.
    pub async fn sample(&self, request: SampleRequest) -> SampleReply {
        self.sample_raw(proto::encode(&request), Duration::from_secs(15)).await.expect("sample reply")
    }

    /// The state query with `k` top priorities.
    pub async fn state(&self, k: u32) -> StatsReport {
        let key = format!("{}?k={k}", replay_server::state_key(self.bus.run()));
        let replies = self
            .bus
            .session()
            .get(key)
            .express(true)
            .timeout(Duration::from_secs(10))
            .await
            .expect("get state");
        let reply = replies.recv_async().await.expect("state reply");
        let sample = reply.result().expect("state ok");
        proto::decode(&sample.payload().to_bytes()).expect("state decodes")
    }

    /// Polls the state until `done` holds.
    pub async fn wait_state(&self, what: &str, mut done: impl FnMut(&StatsReport) -> bool) -> StatsReport {
        within(what, async {
            loop {
                let state = self.state(0).await;
                if done(&state) {
                    return state;
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        })
        .await
    }
}

/// A small Ant-sized configuration for tests.
pub fn test_config() -> ReplayServerConfig {
    let mut cfg = ReplayServerConfig {
        min_size_to_sample: 256,
        max_batch_size: 256,
        // Requests that may be asked before their inserts land wait for them, on a loaded machine too.
        request_deadline_ms: 10_000,
        stats_interval_ms: 100,
        ..ReplayServerConfig::default()
    };
    cfg.buffer.capacity_transitions = 10_000;
    cfg
}

/// Transition `k` of a stream: observation `[k; 105]`, next `[k + 1; 105]` (consecutive transitions
/// share a row), action `k / 1000` alternating in sign, reward `k`, terminated when `k % 7 == 0`.
pub fn ant_batch(executor_id: u32, first: u32, n: u32) -> ExperienceBatch {
    let mut t = Transitions::with_capacity(ANT_OBS, ANT_ACT, n as usize);
    for k in first..first + n {
        let x = k as f32;
        let obs = vec![x; ANT_OBS as usize];
        let next = vec![x + 1.0; ANT_OBS as usize];
        let action: Vec<f32> =
            (0..ANT_ACT).map(|j| if j % 2 == 0 { x / 1000.0 } else { -x / 1000.0 }).collect();
        t.push(proto::Transition {
            observation: &obs,
            action: &action,
            reward: x,
            next_observation: &next,
            terminated: k.is_multiple_of(7),
        })
        .expect("row widths");
    }
    let td_errors = (first..first + n).map(|k| (k % 13) as f32 * 0.1).collect();
    ExperienceBatch {
        executor_id,
        stream: 0,
        seq: 0,
        weights_version: 0,
        env_steps: 0,
        transitions: t,
        td_errors,
    }
}

/// Asserts each row of a sampled batch is transition `reward` of [`ant_batch`], within `inserted`.
pub fn assert_exact_rows(batch: &proto::SampledBatch, inserted: std::ops::Range<u32>) {
    let t = &batch.transitions;
    assert_eq!((t.obs_dim, t.act_dim), (ANT_OBS, ANT_ACT));
    for i in 0..batch.len() {
        let row = t.get(i).expect("row");
        let k = row.reward as u32;
        assert!(inserted.contains(&k), "transition {k} was never inserted");
        assert_eq!(row.reward, k as f32);
        assert!(row.observation.iter().all(|v| *v == k as f32), "observation of {k}");
        assert!(row.next_observation.iter().all(|v| *v == k as f32 + 1.0), "next observation of {k}");
        assert_eq!(row.action[0], k as f32 / 1000.0);
        assert_eq!(row.action[1], -(k as f32) / 1000.0);
        assert_eq!(row.terminated, k.is_multiple_of(7));
    }
    assert_eq!(batch.slots.len(), batch.len());
    assert_eq!(batch.generations.len(), batch.len());
    assert!(batch.is_weights.iter().all(|w| w.is_finite() && *w > 0.0 && *w <= 1.0), "IS weights in (0, 1]");
    assert!(batch.is_weights.contains(&1.0), "IS weights are normalised by the batch maximum");
}

/// The value of a metric in a report.
pub fn metric(report: &StatsReport, name: &str) -> f64 {
    report.metric(name).unwrap_or_else(|| panic!("metric {name} missing"))
}

/// A sample request numbered `id`.
pub fn request(id: u64, batch_size: u32) -> SampleRequest {
    SampleRequest { request_id: id, learner_step: id, batch_size }
}

/// The batch of a reply; panics on a refusal, with its reason.
pub fn batch_of(reply: SampleReply) -> proto::SampledBatch {
    match reply {
        SampleReply::Batch(batch) => batch,
        SampleReply::Refused(refusal) => panic!("refused: {} ({:?})", refusal.reason, refusal),
    }
}
