//! The replay server over zenoh loopback, in one process with three sessions: the server, an
//! inserter publishing batches of 64 Ant transitions as fast as it can, and a sampler pulling
//! batches of 128 (express queries) and sending a priority update after each, as a learner would.
//!
//! `cargo bench -p replay-server --bench zenoh_loopback` runs two phases on a 1M-transition buffer:
//! without snapshots, then with the snapshot replica writing every 3 s once the buffer is full.
//! `-- --test` runs both briefly on 20K transitions (CI). Rates are counted at the server (its
//! state query), CPU from /proc/self/stat.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use node::{Bus, BusConfig, Shutdown};
use proto::{
    ExperienceBatch, NodeId, PriorityUpdate, Role, RunId, SampleReply, SampleRequest, StatsReport, topics,
};
use rand::{Rng, SeedableRng, rngs::StdRng};
use replay_server::ReplayServerConfig;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;

const OBS: u32 = 105;
const ACT: u32 = 8;
const INSERT_BATCH: u32 = 64;
const SAMPLE_BATCH: u32 = 128;

struct Phase {
    name: &'static str,
    capacity: usize,
    snapshots: bool,
    /// Transitions per second the inserter aims at; `None`: as fast as it can.
    insert_rate: Option<f64>,
    window: Duration,
}

fn main() -> anyhow::Result<()> {
    let quick = std::env::args().any(|a| a == "--test");
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let (capacity, window) =
        if quick { (20_000, Duration::from_secs(1)) } else { (1_000_000, Duration::from_secs(10)) };
    println!(
        "zenoh loopback bench: Ant obs {OBS} act {ACT}, inserts of {INSERT_BATCH}, samples of {SAMPLE_BATCH}"
    );
    let paced = Some(200_000.0);
    for phase in [
        Phase {
            name: "no snapshots, inserter flat out",
            capacity,
            snapshots: false,
            insert_rate: None,
            window,
        },
        Phase {
            name: "no snapshots, inserter at 200K/s",
            capacity,
            snapshots: false,
            insert_rate: paced,
            window,
        },
        Phase {
            name: "snapshots every 3 s, inserter at 200K/s",
            capacity,
            snapshots: true,
            insert_rate: paced,
            window,
        },
        Phase {
            name: "snapshots every 3 s, inserter flat out",
            capacity,
            snapshots: true,
            insert_rate: None,
            window,
        },
    ] {
        runtime.block_on(run_phase(&phase))?;
    }
    lock_hold_comparison(capacity)
}

/// What the alternatives to the replica would hold the service's lock for, on a full buffer of
/// `capacity`: cloning the buffer, or serialising it (to memory, so without any disk); and what one
/// chunk of the stats scan holds it for.
fn lock_hold_comparison(capacity: usize) -> anyhow::Result<()> {
    let dims = replay::Dims { obs_dim: OBS as usize, act_dim: ACT as usize };
    let cfg = replay::ReplayConfig { capacity_transitions: capacity, ..Default::default() };
    let mut buffer = replay::ReplayBuffer::new(cfg, dims)?;
    let batches: Vec<ExperienceBatch> =
        payloads().iter().map(|p| proto::decode(&p.to_bytes())).collect::<Result<_, _>>()?;
    let mut i = 0;
    while buffer.len() < capacity {
        let b = &batches[i % batches.len()];
        let t = &b.transitions;
        buffer.insert_batch(replay::TransitionBatch {
            observations: &t.observations,
            actions: &t.actions,
            rewards: &t.rewards,
            next_observations: &t.next_observations,
            terminated: &t.terminated,
            abs_td_errors: Some(&b.td_errors),
        })?;
        i += 1;
    }
    let started = Instant::now();
    let copy = buffer.clone();
    let clone_ms = started.elapsed().as_secs_f64() * 1e3;
    drop(copy);
    let mut bytes =
        Vec::with_capacity(replay::ReplayBuffer::bytes_for(buffer.config(), dims) as usize + 4096);
    let started = Instant::now();
    buffer.write_snapshot(&mut bytes)?;
    let serialise_ms = started.elapsed().as_secs_f64() * 1e3;
    let started = Instant::now();
    let mut scan = replay_server::PriorityScan::new(&buffer, 10);
    let mut chunks = 0u32;
    while !scan.step(&buffer, replay_server::SCAN_CHUNK_TRANSITIONS) {
        chunks += 1;
    }
    let scan_ms = started.elapsed().as_secs_f64() * 1e3;
    println!(
        "\n[lock holds on a full buffer of {capacity}] buffer.clone(): {clone_ms:.0} ms; write_snapshot to memory \
         ({:.0} MB): {serialise_ms:.0} ms; stats/top-k scan: {scan_ms:.1} ms in {} chunks ({:.2} ms each)",
        bytes.len() as f64 / 1e6,
        chunks + 1,
        scan_ms / f64::from(chunks + 1)
    );
    Ok(())
}

/// 16 encoded batches of 64 consecutive random transitions with TD errors.
fn payloads() -> Vec<ZBytes> {
    let mut rng = StdRng::seed_from_u64(0);
    (0..16)
        .map(|seq| {
            let n = INSERT_BATCH as usize;
            let states: Vec<f32> = (0..(n + 1) * OBS as usize).map(|_| rng.random()).collect();
            let batch = ExperienceBatch {
                executor_id: 0,
                stream: 0,
                seq,
                weights_version: 0,
                env_steps: 0,
                transitions: proto::Transitions {
                    obs_dim: OBS,
                    act_dim: ACT,
                    observations: states[..n * OBS as usize].to_vec(),
                    actions: (0..n * ACT as usize).map(|_| rng.random_range(-1.0..1.0)).collect(),
                    rewards: (0..n).map(|_| rng.random()).collect(),
                    next_observations: states[OBS as usize..].to_vec(),
                    terminated: vec![false; n],
                },
                td_errors: (0..n).map(|_| rng.random_range(0.0..5.0)).collect(),
            };
            ZBytes::from(proto::encode(&batch))
        })
        .collect()
}

async fn open(run: &RunId, role: Role, cfg: &BusConfig) -> anyhow::Result<Bus> {
    Ok(Bus::open(run.clone(), NodeId { role, id: 0 }, cfg).await?)
}

async fn state(bus: &Bus) -> anyhow::Result<StatsReport> {
    let replies = bus
        .session()
        .get(replay_server::state_key(bus.run()))
        .express(true)
        .timeout(Duration::from_secs(10))
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let reply = replies.recv_async().await.map_err(|e| anyhow::anyhow!("no state reply: {e}"))?;
    let sample = reply.result().map_err(|e| anyhow::anyhow!("state error: {e:?}"))?;
    Ok(proto::decode(&sample.payload().to_bytes())?)
}

fn metric(report: &StatsReport, name: &str) -> f64 {
    report.metric(name).unwrap_or(0.0)
}

/// User + system CPU seconds of this process.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the command name, which is in parentheses and may hold spaces.
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

async fn run_phase(phase: &Phase) -> anyhow::Result<()> {
    let run = RunId::new(format!("bench-{}", std::process::id()))?;
    let endpoint = format!("tcp/127.0.0.1:{}", node::free_loopback_port()?);
    let dir = std::env::temp_dir().join(format!("replay-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let mut cfg =
        ReplayServerConfig { max_batch_size: SAMPLE_BATCH, stats_interval_ms: 1000, ..Default::default() };
    cfg.buffer.capacity_transitions = phase.capacity;
    cfg.buffer.memory_budget_bytes = 3 << 30;
    cfg.min_size_to_sample = cfg.min_size_to_sample.min(phase.capacity as u64 / 2);
    if phase.snapshots {
        cfg.snapshot_path = Some(dir.join("replay.snap"));
        cfg.snapshot_interval_s = 3;
        // The log must hold what arrives while a snapshot is serialised: at 200K transitions/s
        // (176 MB/s of Ant transitions) and ~0.5 s per 482 MB snapshot, ~100 MB; twice that and
        // room for the replica to catch up.
        cfg.snapshot_log_budget_bytes = 512 << 20;
    }
    let server_cfg = BusConfig { listen: vec![endpoint.clone()], ..Default::default() };
    let server_bus = open(&run, Role::Replay, &server_cfg).await?;
    let (trigger, shutdown) = Shutdown::new();
    // The server gets its own runtime and threads, as it would in its own process.
    let server = std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
        runtime.block_on(replay_server::run(cfg, server_bus, shutdown))
    });
    let client_cfg = BusConfig { connect: vec![endpoint], ..Default::default() };
    let inserter_bus = open(&run, Role::Executor, &client_cfg).await?;
    let sampler_bus = open(&run, Role::Learner, &client_cfg).await?;
    let liveliness = topics::liveliness(&run, NodeId { role: Role::Replay, id: 0 });
    tokio::time::timeout(Duration::from_secs(30), async {
        loop {
            if let Ok(replies) = sampler_bus.session().liveliness().get(&liveliness).await
                && replies.recv_async().await.is_ok()
            {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await?;

    let stop = Arc::new(AtomicBool::new(false));
    let inserter = {
        let stop = Arc::clone(&stop);
        let publisher = inserter_bus
            .session()
            .declare_publisher(topics::experience(&run, 0))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let payloads = payloads();
        let rate = phase.insert_rate;
        tokio::spawn(async move {
            let started = Instant::now();
            let mut i = 0usize;
            while !stop.load(Ordering::Relaxed) {
                if let Some(rate) = rate
                    && (i * INSERT_BATCH as usize) as f64 >= rate * started.elapsed().as_secs_f64()
                {
                    tokio::time::sleep(Duration::from_millis(1)).await;
                    continue;
                }
                if publisher.put(payloads[i % payloads.len()].clone()).await.is_err() {
                    break;
                }
                i += 1;
                // An executor has its own process; here it must leave the sampler some turns.
                tokio::task::yield_now().await;
            }
        })
    };
    let refused = Arc::new(AtomicU64::new(0));
    let measuring = Arc::new(AtomicBool::new(false));
    let latencies_us = Arc::new(std::sync::Mutex::new(Vec::<u32>::new()));
    let sampler = {
        let (stop, refused, bus) = (Arc::clone(&stop), Arc::clone(&refused), sampler_bus.clone());
        let (measuring, latencies_us) = (Arc::clone(&measuring), Arc::clone(&latencies_us));
        tokio::spawn(async move {
            let mut rng = StdRng::seed_from_u64(1);
            let mut id = 0u64;
            while !stop.load(Ordering::Relaxed) {
                id += 1;
                let request = SampleRequest { request_id: id, learner_step: id, batch_size: SAMPLE_BATCH };
                let asked = Instant::now();
                let Ok(replies) = bus
                    .session()
                    .get(topics::replay_sample(bus.run()))
                    .payload(proto::encode(&request))
                    .express(true)
                    .timeout(Duration::from_secs(10))
                    .await
                else {
                    break;
                };
                let Ok(reply) = replies.recv_async().await else { continue };
                let Ok(sample) = reply.result() else { continue };
                match proto::decode::<SampleReply>(&sample.payload().to_bytes()) {
                    Ok(SampleReply::Batch(batch)) => {
                        if measuring.load(Ordering::Relaxed)
                            && let Ok(mut l) = latencies_us.lock()
                        {
                            l.push(asked.elapsed().as_micros() as u32);
                        }
                        let update = PriorityUpdate {
                            learner_step: id,
                            td_errors: (0..batch.len()).map(|_| rng.random_range(0.0..5.0)).collect(),
                            slots: batch.slots,
                            generations: batch.generations,
                        };
                        if bus.put(proto::Topic::ReplayPriorities, &update).await.is_err() {
                            break;
                        }
                    }
                    _ => {
                        refused.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        })
    };

    // Warm up; in the snapshot phase, fill the buffer first so snapshots are full-size.
    let fill_started = Instant::now();
    loop {
        tokio::time::sleep(Duration::from_millis(200)).await;
        let s = state(&sampler_bus).await?;
        let full = metric(&s, "replay/size_transitions") >= phase.capacity as f64;
        if (!phase.snapshots && fill_started.elapsed() > Duration::from_secs(1)) || (phase.snapshots && full)
        {
            break;
        }
        anyhow::ensure!(fill_started.elapsed() < Duration::from_secs(300), "buffer did not fill in 300 s");
    }
    let before = state(&sampler_bus).await?;
    let (t0, cpu0) = (Instant::now(), cpu_seconds());
    measuring.store(true, Ordering::Relaxed);
    tokio::time::sleep(phase.window).await;
    measuring.store(false, Ordering::Relaxed);
    let after = state(&sampler_bus).await?;
    let (dt, cpu) = (t0.elapsed().as_secs_f64(), cpu_seconds() - cpu0);
    stop.store(true, Ordering::Relaxed);
    let delta = |name: &str| (metric(&after, name) - metric(&before, name)) / dt;
    println!("\n[{}] capacity {}, window {dt:.1} s", phase.name, phase.capacity);
    if phase.snapshots {
        println!("  filled to {} in {:.1} s", phase.capacity, fill_started.elapsed().as_secs_f64() - dt);
    }
    println!(
        "  inserts: {:.0} transitions/s ({:.0} messages/s of {INSERT_BATCH})",
        delta("replay/inserted_transitions_total"),
        delta("replay/inserted_transitions_total") / f64::from(INSERT_BATCH)
    );
    println!(
        "  samples: {:.0} batches/s of {SAMPLE_BATCH}, priority updates {:.0}/s",
        delta("replay/sampled_batches_total"),
        delta("replay/priority_updates_applied_total") + delta("replay/priority_updates_stale_total")
    );
    let mut latencies = latencies_us.lock().map(|l| l.clone()).unwrap_or_default();
    latencies.sort_unstable();
    let pct = |q: f64| {
        latencies.get(((latencies.len() as f64 * q) as usize).min(latencies.len().saturating_sub(1)))
    };
    if let (Some(p50), Some(p99), Some(max)) = (pct(0.5), pct(0.99), latencies.last()) {
        println!("  sample round trip (request to decoded batch): p50 {p50} µs, p99 {p99} µs, max {max} µs");
    }
    println!("  process CPU: {:.2} cores (server, both clients and zenoh)", cpu / dt);
    println!(
        "  size {}, refused {}, rejected {}",
        metric(&after, "replay/size_transitions"),
        refused.load(Ordering::Relaxed),
        metric(&after, "replay/rejected_total")
    );
    let _ = tokio::time::timeout(Duration::from_secs(20), inserter).await;
    let _ = tokio::time::timeout(Duration::from_secs(20), sampler).await;
    trigger.fire();
    let shutdown_started = Instant::now();
    let report = tokio::task::spawn_blocking(move || server.join())
        .await?
        .map_err(|_| anyhow::anyhow!("server thread panicked"))??;
    if phase.snapshots {
        println!(
            "  snapshots: {} written ({} aborted, {} failed), last serialise {:.0} ms, {:.0} MB; \
             service held per snapshot request: {:?} µs",
            metric(&after, "replay/snapshots_written_total"),
            metric(&after, "replay/snapshots_aborted_total"),
            metric(&after, "replay/snapshots_failed_total"),
            metric(&after, "replay/snapshot_last_serialise_ms"),
            metric(&after, "replay/snapshot_last_bytes") / 1e6,
            report.snapshots.request_pauses_us,
        );
        println!("  shutdown incl. final snapshot: {:.2} s", shutdown_started.elapsed().as_secs_f64());
    }
    inserter_bus.close().await?;
    sampler_bus.close().await?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
