//! The in-process cluster harness: every role's `run` in one process, each on its own zenoh peer
//! session over loopback (the replay server listens on a free port, the others connect to it and
//! find each other by gossip), with the real Ant and tiny networks. Readiness is a liveliness token,
//! never a sleep; every wait has a deadline. acme's `test_mt` and raft-rs's `harness/`, in Rust.
//!
//! ```no_run
//! # async fn demo() -> anyhow::Result<()> {
//! let mut cluster = cluster::Cluster::start(cluster::Spec::tiny("demo", 2)).await?;
//! cluster.wait_for_learner_step(100).await?;
//! let reports = cluster.stop().await?;
//! assert!(reports.learner.updater.final_step >= 100);
//! # Ok(()) }
//! ```

pub mod audit;

use std::collections::{BTreeMap, HashMap};
use std::future::Future;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use node::{Bus, BusConfig, Faults, Shutdown, ShutdownTrigger};
use proto::{GlobalStep, LearnerStep, Message, NodeId, Role, RunId, topics};
use run::RoleConfig;
use tokio::task::JoinHandle;

/// The longest any single wait of the harness may take.
pub const WAIT: Duration = Duration::from_secs(120);

/// Awaits `f`, or fails with what was awaited after `limit`.
pub async fn within<T>(what: &str, limit: Duration, f: impl Future<Output = T>) -> Result<T> {
    tokio::time::timeout(limit, f).await.map_err(|_| anyhow!("timed out after {limit:?} waiting for {what}"))
}

/// What to start.
#[derive(Debug, Clone)]
pub struct Spec {
    /// The run id.
    pub run_id: String,
    /// Executors started with the cluster (ids 0..n).
    pub executors: u32,
    /// The run file, TOML; every role reads its tables from it.
    pub config: String,
}

impl Spec {
    /// Tiny networks on the real Ant, short episodes, a small replay minimum, frequent weights.
    pub fn tiny(run_id: &str, executors: u32) -> Spec {
        let config = include_str!("../../deploy/configs/tiny.toml");
        Spec { run_id: run_id.into(), executors, config: config.into() }
    }

    /// [`Spec::tiny`] with durable experience under `dir`: the replay server snapshots every second
    /// to `dir/replay.snap` (with a replica log small enough for the tiny memory budget) and executors
    /// spool into `dir/spool`, which is returned for the audit.
    pub fn tiny_durable(run_id: &str, executors: u32, dir: &std::path::Path) -> (Spec, std::path::PathBuf) {
        let mut spec = Spec::tiny(run_id, executors);
        let (snapshot, spools) = (dir.join("replay.snap"), dir.join("spool"));
        let replay = format!(
            "[replay_server]\nsnapshot_path = {:?}\nsnapshot_interval_s = 1\nsnapshot_log_budget_bytes = 16777216\n",
            snapshot.display().to_string()
        );
        let executor = format!("[executor]\nspool_dir = {:?}\n", spools.display().to_string());
        spec.config = spec.config.replace("[replay_server]\n", &replay).replace("[executor]\n", &executor);
        (spec, spools)
    }
}

impl Spec {
    /// [`Spec::tiny`] in deterministic mode: rounds of 25 updates (the tiny weights period), 10 env
    /// steps per executor per round, no evaluations; the learner checkpoints into `dir` every 500
    /// updates and stops at `max_updates`, and the replay server cuts its state into `dir` at each
    /// checkpoint, so the run resumes from `dir`.
    pub fn tiny_deterministic(run_id: &str, executors: u32, dir: &std::path::Path, max_updates: u64) -> Spec {
        let mut spec = Spec::tiny(run_id, executors);
        let path = |name: &str| format!("{:?}", dir.join(name).display().to_string());
        let learner = format!(
            "[learner]\nmax_updates = {max_updates}\ncheckpoint_dir = {}\ncheckpoint_every_epochs = 5\n",
            path("checkpoints")
        );
        let replay = format!(
            "[replay_server]\nsnapshot_path = {}\nsnapshot_log_budget_bytes = 16777216\n",
            path("replay.snap")
        );
        spec.config = spec
            .config
            .replace("[train]\n", "[train]\ndeterministic = true\n")
            .replace("[learner]\n", &learner)
            .replace("[replay_server]\n", &replay)
            .replace("eval_episodes = 1", "eval_episodes = 0");
        spec.config.push_str(&format!(
            "\n[lockstep]\nexecutors = {executors}\nwarm_up_transitions = 300\nupdates_per_round = 25\n\
             env_steps_per_round = 10\n"
        ));
        spec
    }
}

/// Parses and validates role config `C` from a run file's text.
pub fn role_config<C: RoleConfig>(text: &str) -> Result<C> {
    let config = C::parse(text).map_err(|e| anyhow!("[{}]: {e}", C::SECTION))?;
    config.validate().map_err(|e| anyhow!("[{}] invalid: {e}", C::SECTION))?;
    Ok(config)
}

/// One running role.
#[derive(Debug)]
pub struct Running<R> {
    trigger: ShutdownTrigger,
    task: JoinHandle<Result<R>>,
}

impl<R> Running<R> {
    async fn stop(self, what: &str) -> Result<R> {
        self.trigger.fire();
        within(what, WAIT, self.task).await?.with_context(|| format!("{what} panicked"))?
    }
}

/// Messages gathered by [`Cluster::collect`].
#[derive(Debug)]
pub struct Collected<M> {
    messages: Arc<Mutex<Vec<M>>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl<M: Clone> Collected<M> {
    /// A copy of what arrived so far.
    pub fn snapshot(&self) -> Vec<M> {
        self.messages.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// Waits until what arrived satisfies `pred`.
    pub async fn wait_until(&self, what: &str, pred: impl Fn(&[M]) -> bool) -> Result<()> {
        within(what, WAIT, async {
            while !pred(&self.snapshot()) {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
        .await
    }
}

/// What every role returned.
#[derive(Debug)]
pub struct Reports {
    /// The replay server's.
    pub replay: replay_server::Report,
    /// The param server's.
    pub param: param_server::Report,
    /// The learner's.
    pub learner: learner::Report,
    /// Each executor still running at the end, by id.
    pub executors: BTreeMap<u32, executor::Report>,
}

/// A running cluster.
#[derive(Debug)]
pub struct Cluster {
    run: RunId,
    endpoint: String,
    config: String,
    /// A session of the harness's own, for watching the run's topics.
    pub observer: Bus,
    /// Every process's fault rules.
    pub network: Network,
    replay: Running<replay_server::Report>,
    param: Running<param_server::Report>,
    learner: Running<learner::Report>,
    executors: BTreeMap<u32, Running<executor::Report>>,
}

/// The fault rules of every process of a cluster, by node: a test installs rules on a node's
/// [`Faults`] (before [`Cluster::start_with`], or while it runs) to drop, delay or cut its messages per
/// topic; a restarted role keeps its node's rules.
#[derive(Debug, Clone, Default)]
pub struct Network {
    by_node: Arc<Mutex<HashMap<NodeId, Faults>>>,
}

impl Network {
    /// `node`'s rules (empty until some are added).
    pub fn faults(&self, node: NodeId) -> Faults {
        self.by_node.lock().unwrap_or_else(PoisonError::into_inner).entry(node).or_default().clone()
    }

    /// The rules of `role`'s process `id`.
    pub fn of(&self, role: Role, id: u32) -> Faults {
        self.faults(NodeId { role, id })
    }

    async fn open(&self, run: &RunId, role: Role, id: u32, config: &BusConfig) -> Result<Bus> {
        let node = NodeId { role, id };
        let bus =
            Bus::open(run.clone(), node, config).await.with_context(|| format!("opening {role} {id}"))?;
        Ok(bus.with_faults(self.faults(node)))
    }
}

impl Cluster {
    /// Starts the replay server, param server, learner and `spec.executors` executors; returns once
    /// each has declared its liveliness token.
    pub async fn start(spec: Spec) -> Result<Cluster> {
        Self::start_with(spec, Network::default()).await
    }

    /// [`Cluster::start`] with the fault rules of `network` (some may be installed already, to act
    /// from the first message).
    pub async fn start_with(spec: Spec, network: Network) -> Result<Cluster> {
        let run = RunId::new(spec.run_id.clone())?;
        let endpoint = format!("tcp/127.0.0.1:{}", node::free_loopback_port()?);
        let server = BusConfig { listen: vec![endpoint.clone()], ..BusConfig::default() };
        let peer = BusConfig::loopback(vec![endpoint.clone()]);
        let replay_bus = network.open(&run, Role::Replay, 0, &server).await?;
        let replay_config = role_config(&spec.config)?;
        let replay = spawn(|s| replay_server::run(replay_config, replay_bus, s));
        let observer = network.open(&run, Role::Learner, 9999, &peer).await?;
        let param_bus = network.open(&run, Role::Param, 0, &peer).await?;
        let param_config = role_config(&spec.config)?;
        let param = spawn(|s| param_server::run(param_config, param_bus, s));
        let learner_bus = network.open(&run, Role::Learner, 0, &peer).await?;
        let learner_config = role_config(&spec.config)?;
        let learner = spawn(|s| learner::run(learner_config, learner_bus, s));
        let mut cluster = Cluster {
            run,
            endpoint,
            config: spec.config,
            observer,
            network,
            replay,
            param,
            learner,
            executors: BTreeMap::new(),
        };
        for (role, id) in [(Role::Replay, 0), (Role::Param, 0), (Role::Learner, 0)] {
            cluster.wait_alive(NodeId { role, id }).await?;
        }
        for id in 0..spec.executors {
            cluster.start_executor(id).await?;
        }
        Ok(cluster)
    }

    /// The run id.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// Starts executor `id` (a late joiner if the run is under way); returns once it is alive.
    pub async fn start_executor(&mut self, id: u32) -> Result<()> {
        if self.executors.contains_key(&id) {
            bail!("executor {id} is already running");
        }
        let bus = self
            .network
            .open(&self.run, Role::Executor, id, &BusConfig::loopback(vec![self.endpoint.clone()]))
            .await?;
        let config = role_config(&self.config)?;
        let running = spawn(|s| executor::run(config, bus, s));
        self.executors.insert(id, running);
        self.wait_alive(NodeId { role: Role::Executor, id }).await
    }

    /// Stops the learner cleanly (it writes its final checkpoint when the run file gives it a
    /// `checkpoint_dir`) and starts a new one, which resumes from that checkpoint. Returns the old
    /// learner's report once the new one is alive.
    pub async fn restart_learner(&mut self) -> Result<learner::Report> {
        // Its checkpoint is read at start, so the old one must have stopped (and written it) first.
        self.learner.trigger.fire();
        let stopped = within("the old learner to stop", WAIT, &mut self.learner.task).await?;
        let report = stopped.context("the old learner panicked")??;
        let bus = self
            .network
            .open(&self.run, Role::Learner, 0, &BusConfig::loopback(vec![self.endpoint.clone()]))
            .await?;
        let config = role_config(&self.config)?;
        self.learner = spawn(|s| learner::run(config, bus, s));
        self.wait_alive(NodeId { role: Role::Learner, id: 0 }).await?;
        Ok(report)
    }

    /// Stops the replay server cleanly and starts a new one on the same endpoint. Without a
    /// `snapshot_path` it comes back empty: the learner starves until executors refill it.
    pub async fn restart_replay(&mut self) -> Result<replay_server::Report> {
        self.replay.trigger.fire();
        let stopped = within("the old replay server to stop", WAIT, &mut self.replay.task).await?;
        let report = stopped.context("the old replay server panicked")??;
        self.start_replay().await?;
        Ok(report)
    }

    /// Kills the replay server without a clean shutdown (no final snapshot): its task is aborted,
    /// its session dropped, as a crashed process's would be. [`Cluster::start_replay`] starts the
    /// next one.
    pub async fn kill_replay(&mut self) -> Result<()> {
        self.replay.task.abort();
        let _ = within("the killed replay server's task", WAIT, &mut self.replay.task).await?;
        let (trigger, _) = Shutdown::new();
        std::mem::forget(std::mem::replace(&mut self.replay.trigger, trigger));
        Ok(())
    }

    /// Starts a replay server on the run's endpoint (after [`Cluster::kill_replay`]); it restores
    /// the run file's snapshot if there is one. Returns once it is alive.
    pub async fn start_replay(&mut self) -> Result<()> {
        let server = BusConfig { listen: vec![self.endpoint.clone()], ..BusConfig::default() };
        // A killed server's session is closed in the background: its listener may hold the port a
        // little longer, as a crashed process's socket would.
        let bus = within("the replay server's port to be free", WAIT, async {
            loop {
                match self.network.open(&self.run, Role::Replay, 0, &server).await {
                    Err(e) if format!("{e:#}").contains("Address already in use") => {
                        tokio::time::sleep(Duration::from_millis(50)).await;
                    }
                    opened => return opened,
                }
            }
        })
        .await??;
        let config = role_config(&self.config)?;
        self.replay = spawn(|s| replay_server::run(config, bus, s));
        self.wait_alive(NodeId { role: Role::Replay, id: 0 }).await
    }

    /// Kills executor `id` without a clean shutdown: its task is aborted mid-step, its session
    /// dropped, so its liveliness token vanishes as a crashed process's would.
    pub async fn kill_executor(&mut self, id: u32) -> Result<()> {
        let running = self.executors.remove(&id).ok_or_else(|| anyhow!("no executor {id}"))?;
        running.task.abort();
        let _ = within("the killed executor's task", WAIT, running.task).await?;
        std::mem::forget(running.trigger); // dropping it would fire a clean shutdown signal
        Ok(())
    }

    /// Waits until `node`'s liveliness token is visible.
    pub async fn wait_alive(&self, node: NodeId) -> Result<()> {
        let key = topics::liveliness(&self.run, node);
        let session = self.observer.session();
        within(&format!("{} {} to be alive", node.role, node.id), WAIT, async {
            loop {
                if let Ok(replies) = session.liveliness().get(&key).timeout(Duration::from_secs(1)).await
                    && replies.recv_async().await.is_ok()
                {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
        .await
    }

    /// Waits until a message on `key` satisfies `pred`; returns it.
    pub async fn wait_for<M: Message>(&self, what: &str, key: &str, pred: impl Fn(&M) -> bool) -> Result<M> {
        let sub = self.observer.session().declare_subscriber(key).await.map_err(node::NodeError::zenoh)?;
        within(what, WAIT, async {
            loop {
                let sample = sub.recv_async().await.map_err(|e| anyhow!("{e}"))?;
                if let Ok(message) = proto::decode::<M>(&sample.payload().to_bytes())
                    && pred(&message)
                {
                    return Ok(message);
                }
            }
        })
        .await?
    }

    /// Waits until the learner reports a step of at least `step` on `control/learner`.
    pub async fn wait_for_learner_step(&self, step: u64) -> Result<u64> {
        let (key, what) = (topics::control_learner(&self.run), format!("learner step {step}"));
        let reached = self.wait_for::<LearnerStep>(&what, &key, |s| s.learner_step >= step).await?;
        Ok(reached.learner_step)
    }

    /// Waits until a `control/step` announcement satisfies `pred`; returns it.
    pub async fn wait_for_global_step(
        &self,
        what: &str,
        pred: impl Fn(&GlobalStep) -> bool,
    ) -> Result<GlobalStep> {
        self.wait_for(what, &topics::control_step(&self.run), pred).await
    }

    /// Collects every decodable message on `key` from now on, until the returned value is dropped.
    pub async fn collect<M: Message + Send + 'static>(&self, key: &str) -> Result<Collected<M>> {
        let messages: Arc<Mutex<Vec<M>>> = Arc::default();
        let sink = messages.clone();
        let subscriber = self
            .observer
            .session()
            .declare_subscriber(key)
            .callback(move |sample| {
                if let Ok(message) = proto::decode::<M>(&sample.payload().to_bytes()) {
                    sink.lock().unwrap_or_else(PoisonError::into_inner).push(message);
                }
            })
            .await
            .map_err(node::NodeError::zenoh)?;
        Ok(Collected { messages, _subscriber: subscriber })
    }

    /// Stops every role (executors first, the replay server last) and returns their reports.
    pub async fn stop(self) -> Result<Reports> {
        self.stop_after_learner(false).await
    }

    /// Waits for the learner to end by itself (at `max_updates`), then stops the others as
    /// [`Cluster::stop`] does.
    pub async fn finish(self) -> Result<Reports> {
        self.stop_after_learner(true).await
    }

    async fn stop_after_learner(self, learner_ends_itself: bool) -> Result<Reports> {
        let Cluster { learner, executors: running, param, replay, .. } = self;
        let (mut learner, mut ended) = (Some(learner), None);
        if learner_ends_itself && let Some(learner) = learner.take() {
            let joined = within("the learner to reach max_updates", WAIT, learner.task).await?;
            ended = Some(joined.context("the learner panicked")??);
        }
        let mut executors = BTreeMap::new();
        for (id, running) in running {
            executors.insert(id, running.stop(&format!("executor {id} to stop")).await?);
        }
        let learner = match (learner, ended) {
            (Some(learner), _) => learner.stop("the learner to stop").await?,
            (None, ended) => ended.ok_or_else(|| anyhow!("the learner's report is missing"))?,
        };
        let param = param.stop("the param server to stop").await?;
        let replay = replay.stop("the replay server to stop").await?;
        Ok(Reports { replay, param, learner, executors })
    }
}

fn spawn<R, F, Fut>(f: F) -> Running<R>
where
    F: FnOnce(Shutdown) -> Fut,
    Fut: Future<Output = Result<R>> + Send + 'static,
    R: Send + 'static,
{
    let (trigger, shutdown) = Shutdown::new();
    Running { trigger, task: tokio::spawn(f(shutdown)) }
}
