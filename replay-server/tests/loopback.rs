//! The replay server over loopback zenoh: a publisher and a sampler against it, blocking with
//! deadlines and reasons, and restart from snapshots (graceful and killed). The flood of malformed
//! messages is in `flood.rs`, a binary of its own: it fills zenoh's shared receive threads.

mod support;

use std::collections::BTreeMap;
use std::time::Duration;

use proto::{NodeId, PriorityUpdate, RefusalReason, Role, SampleReply, StatsReport, topics};
use replay_server::ReplayServerConfig;
use support::{Client, Server, ant_batch, assert_exact_rows, batch_of, metric, request, test_config, within};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("replay-server-it-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn publisher_and_sampler_get_exact_batches_and_stats() {
    let (server, client) = Server::start("it-basic", test_config()).await;
    let stats_key = topics::stats(&server.run, NodeId { role: Role::Replay, id: 0 });
    let stats = client.bus.session().declare_subscriber(stats_key).await.expect("stats subscriber");
    for i in 0..10 {
        client.put_batch(&ant_batch(i % 2, i * 64, 64)).await;
    }
    // The sampler may ask before every batch has landed: the request waits for the minimum size.
    let batch = batch_of(client.sample(request(1, 128)).await);
    assert_eq!((batch.request_id, batch.len()), (1, 128));
    assert_exact_rows(&batch, 0..640);
    client.wait_state("640 transitions", |s| metric(s, "replay/size_transitions") == 640.0).await;

    // A large TD error on the sampled slots puts them on top of the top-k.
    let update = PriorityUpdate {
        learner_step: 1,
        slots: batch.slots.clone(),
        generations: batch.generations.clone(),
        td_errors: vec![50.0; batch.len()],
    };
    client.bus.put(proto::Topic::ReplayPriorities, &update).await.expect("put priorities");
    let state = client
        .wait_state("the priority update", |s| metric(s, "replay/priority_updates_applied_total") == 128.0)
        .await;
    assert!(state.metrics.iter().all(|m| !m.name.starts_with("replay/top.")), "k=0 asks for no top-k");
    let top = client.state(5).await;
    let expected = (50.0f64 + 1e-6).sqrt();
    for rank in 0..5 {
        let p = metric(&top, &format!("replay/top.{rank}.priority"));
        assert!((p - expected).abs() < 1e-9, "rank {rank}: {p}");
        let slot = metric(&top, &format!("replay/top.{rank}.slot")) as u64;
        assert!(batch.slots.contains(&slot));
    }
    assert_eq!(metric(&top, "replay/priority_max"), metric(&top, "replay/top.0.priority"));

    // The periodic stats report carries the figures the issue lists.
    let report: StatsReport = within("a stats report", async {
        loop {
            let sample = stats.recv_async().await.expect("stats sample");
            let report: StatsReport = proto::decode(&sample.payload().to_bytes()).expect("stats decode");
            if report.metric("replay/sampled_batches_total") == Some(1.0)
                && report.metric("replay/priority_updates_applied_total") == Some(128.0)
            {
                return report;
            }
        }
    })
    .await;
    for name in [
        "replay/size_transitions",
        "replay/inserts_per_s",
        "replay/batches_per_s",
        "replay/priority_min",
        "replay/priority_max",
        "replay/priority_mean",
        "replay/ess",
        "replay/rejected_total",
    ] {
        metric(&report, name);
    }
    let ess = metric(&report, "replay/ess");
    assert!(ess > 0.0 && ess <= 1.0);
    let r = server.stop().await;
    assert_eq!(r.counters.inserted_transitions, 640);
    assert_eq!(r.counters.sampled_batches, 1);
    assert_eq!(r.counters.priorities_applied, 128);
    assert!(r.rejected.is_empty(), "{:?}", r.rejected);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn blocked_requests_are_answered_by_inserts_or_refused_at_the_deadline() {
    // Long enough for the 50 ms stats topic to show a waiting request on a loaded machine.
    let cfg = ReplayServerConfig { request_deadline_ms: 2000, stats_interval_ms: 50, ..test_config() };
    let (server, client) = Server::start("it-blocked", cfg).await;
    // Nothing inserted: refused at the deadline with the reason, never a hang.
    let started = std::time::Instant::now();
    match client.sample(request(1, 32)).await {
        SampleReply::Refused(refusal) => {
            assert_eq!(refusal.request_id, 1);
            assert_eq!(refusal.reason, RefusalReason::BelowMinSize { have: 0, min: 256 });
            assert!(refusal.retry_after_ms >= 1 && refusal.retry_after_ms <= 2000);
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    let waited = started.elapsed();
    assert!(waited >= Duration::from_millis(1990) && waited < Duration::from_secs(10), "{waited:?}");

    // While a request waits, the stats topic says what waits and why.
    let stats_key = topics::stats(&server.run, NodeId { role: Role::Replay, id: 0 });
    let stats = client.bus.session().declare_subscriber(stats_key).await.expect("stats subscriber");
    let waiting = {
        let client = Client::connect(&server.run, &server.endpoint).await;
        client.wait_ready().await;
        tokio::spawn(async move { client.sample(request(2, 32)).await })
    };
    let blocked = within("a blocked entry on the stats topic", async {
        loop {
            let sample = stats.recv_async().await.expect("stats");
            let report: StatsReport = proto::decode(&sample.payload().to_bytes()).expect("decode");
            if let Some(b) = report.blocked.into_iter().find(|b| b.what == "replay/sample") {
                return b;
            }
        }
    })
    .await;
    assert!(blocked.why.starts_with("below min size 256 (have 0)"), "{}", blocked.why);
    // Inserts during the wait release it: the reply is a batch.
    let waiting_result = {
        for i in 0..2 {
            client.put_batch(&ant_batch(0, i * 128, 128)).await;
        }
        within("the released request", waiting).await.expect("task")
    };
    match waiting_result {
        SampleReply::Batch(batch) => assert_exact_rows(&batch, 0..256),
        // On a very slow machine the deadline may pass first: still an answer, with the reason.
        SampleReply::Refused(refusal) => {
            assert!(matches!(refusal.reason, RefusalReason::BelowMinSize { .. }))
        }
    }
    let too_big = client.sample(request(3, 257)).await;
    assert!(matches!(
        too_big,
        SampleReply::Refused(r) if r.reason == RefusalReason::BatchTooLarge { requested: 257, max: 256 }
    ));
    let report = server.stop().await;
    assert!(report.counters.refused["below_min_size"] >= 1);
    assert_eq!(report.counters.refused["batch_too_large"], 1);
    assert!(report.counters.blocked_ms["below_min_size"] >= 1990);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn waiting_requests_are_refused_at_shutdown() {
    let cfg = ReplayServerConfig { request_deadline_ms: 10_000, ..test_config() };
    let (server, client) = Server::start("it-shutdown", cfg).await;
    let waiting = tokio::spawn(async move { client.sample(request(1, 32)).await });
    // The request is held once the state shows it waiting.
    let observer = Client::connect(&server.run, &server.endpoint).await;
    observer.wait_ready().await;
    observer.wait_state("a waiting request", |s| metric(s, "replay/pending_requests") == 1.0).await;
    let report = server.stop().await;
    match within("the reply", waiting).await.expect("task") {
        SampleReply::Refused(r) => assert_eq!(r.reason, RefusalReason::ShuttingDown),
        other => panic!("expected a shutdown refusal, got {other:?}"),
    }
    assert_eq!(report.counters.refused["shutting_down"], 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rate_limiter_holds_the_sampler_to_the_ratio() {
    let cfg = ReplayServerConfig {
        samples_per_insert: Some(2.0),
        samples_per_insert_tolerance: 256.0,
        request_deadline_ms: 200,
        ..test_config()
    };
    let (server, client) = Server::start("it-ratio", cfg).await;
    client.put_batch(&ant_batch(0, 0, 256)).await;
    // Landed first: the 200 ms deadline is for the refusal below, not for a slow insert.
    client.wait_state("256 transitions", |s| metric(s, "replay/size_transitions") == 256.0).await;
    // At the minimum size the tolerance (256) is available: two batches of 128, then a refusal.
    batch_of(client.sample(request(1, 128)).await);
    batch_of(client.sample(request(2, 128)).await);
    match client.sample(request(3, 128)).await {
        SampleReply::Refused(r) => assert!(matches!(r.reason, RefusalReason::RateLimited { .. }), "{r:?}"),
        other => panic!("expected rate limiting, got {other:?}"),
    }
    // 64 more inserts earn 128 samples.
    client.put_batch(&ant_batch(0, 256, 64)).await;
    client.wait_state("320 transitions", |s| metric(s, "replay/size_transitions") == 320.0).await;
    batch_of(client.sample(request(4, 128)).await);
    let report = server.stop().await;
    assert_eq!(report.counters.sampled_batches, 3);
    assert_eq!(report.counters.refused["rate_limited"], 1);
}

/// What a restart must preserve, read through the state query.
fn durable_view(state: &StatsReport) -> BTreeMap<String, u64> {
    state
        .metrics
        .iter()
        .filter(|m| {
            m.name.starts_with("replay/top.")
                || m.name.ends_with("_total")
                || ["replay/size_transitions", "replay/priority_min", "replay/priority_max"]
                    .contains(&m.name.as_str())
        })
        .filter(|m| !m.name.starts_with("replay/snapshots_"))
        .map(|m| (m.name.clone(), m.value.to_bits()))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn graceful_restart_restores_contents_priorities_and_counters() {
    let dir = temp_dir("graceful");
    let cfg = ReplayServerConfig { snapshot_path: Some(dir.join("replay.snap")), ..test_config() };
    let (server, client) = Server::start("it-restart", cfg.clone()).await;
    for i in 0..8 {
        client.put_batch(&ant_batch(0, i * 64, 64)).await;
    }
    client.put_raw(0, vec![0xFF; 40]).await;
    let batch = batch_of(client.sample(request(1, 64)).await);
    let update = PriorityUpdate {
        learner_step: 1,
        slots: batch.slots.clone(),
        generations: batch.generations.clone(),
        td_errors: (0..64).map(|i| i as f32).collect(),
    };
    client.bus.put(proto::Topic::ReplayPriorities, &update).await.expect("put");
    let before = client
        .wait_state("inserts, update and rejection", |s| {
            metric(s, "replay/priority_updates_applied_total") == 64.0
                && metric(s, "replay/rejected_total") == 1.0
        })
        .await;
    let before = durable_view(&client.state(20).await)
        .into_iter()
        .chain(durable_view(&before))
        .collect::<BTreeMap<_, _>>();
    let first = server.stop().await;
    assert_eq!(first.snapshots.final_sequence, Some(1));
    assert_eq!(first.snapshots.failed, 0);

    let (server, client) = Server::start("it-restart", cfg).await;
    let after = durable_view(&client.state(20).await)
        .into_iter()
        .chain(durable_view(&client.state(0).await))
        .collect::<BTreeMap<_, _>>();
    assert_eq!(after, before);
    let second = server.stop().await;
    assert_eq!(second.restored_sequence, Some(1));
    assert_eq!(second.snapshots.final_sequence, Some(2));
    assert_eq!(second.counters, first.counters);
    assert_eq!(second.rejected, first.rejected);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// The `replay-server` binary as a child process, killed (SIGKILL) when dropped.
struct Process {
    child: std::process::Child,
    endpoint: String,
}

impl Process {
    fn spawn(config: &std::path::Path, log: &std::path::Path) -> Process {
        let endpoint = format!("tcp/127.0.0.1:{}", node::free_loopback_port().expect("a free loopback port"));
        let child = std::process::Command::new(env!("CARGO_BIN_EXE_replay-server"))
            .args(["--run-id", "it-killed", "--listen", &endpoint, "--config"])
            .arg(config)
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(log).expect("log file"))
            .spawn()
            .expect("start the replay-server binary");
        Process { child, endpoint }
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killed_process_restarts_from_its_periodic_snapshot() {
    let dir = temp_dir("killed");
    let config = dir.join("run.toml");
    let snapshot = dir.join("replay.snap");
    std::fs::write(
        &config,
        format!(
            "[replay_server]\nmin_size_to_sample = 256\nmax_batch_size = 256\nstats_interval_ms = 100\n\
             request_deadline_ms = 10000\n\
             snapshot_path = {:?}\nsnapshot_interval_s = 1\n[replay]\ncapacity_transitions = 10000\n",
            snapshot.display().to_string()
        ),
    )
    .expect("write config");
    let run = proto::RunId::new("it-killed").expect("run id");
    let first = Process::spawn(&config, &dir.join("first.log"));
    let client = Client::connect(&run, &first.endpoint).await;
    client.wait_ready().await;
    for i in 0..5 {
        client.put_batch(&ant_batch(0, i * 100, 100)).await;
    }
    let batch = batch_of(client.sample(request(1, 100)).await);
    let update = PriorityUpdate {
        learner_step: 1,
        slots: batch.slots.clone(),
        generations: batch.generations.clone(),
        td_errors: vec![9.0; 100],
    };
    client.bus.put(proto::Topic::ReplayPriorities, &update).await.expect("put");
    let before = client
        .wait_state("500 transitions and the update", |s| {
            metric(s, "replay/size_transitions") == 500.0
                && metric(s, "replay/priority_updates_applied_total") == 100.0
        })
        .await;
    // The report reads its counters and the last requested snapshot number under one lock hold, so
    // a snapshot numbered above that was requested after the inserts and the update.
    let requested = metric(&before, "replay/snapshot_requested_sequence");
    let before = durable_view(&client.state(20).await)
        .into_iter()
        .chain(durable_view(&before))
        .collect::<BTreeMap<_, _>>();
    client
        .wait_state("a snapshot after the inserts", |s| {
            metric(s, "replay/snapshot_last_sequence") > requested
        })
        .await;
    drop(first); // SIGKILL: no shutdown, no final snapshot.
    drop(client);

    let second = Process::spawn(&config, &dir.join("second.log"));
    let client = Client::connect(&run, &second.endpoint).await;
    client.wait_ready().await;
    let after = durable_view(&client.state(20).await)
        .into_iter()
        .chain(durable_view(&client.state(0).await))
        .collect::<BTreeMap<_, _>>();
    assert_eq!(after, before);
    // And it serves from the restored contents.
    let batch = batch_of(client.sample(request(2, 128)).await);
    assert_exact_rows(&batch, 0..500);
    drop(second);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deadlocking_configuration_is_refused_at_start() {
    let cfg = ReplayServerConfig { min_size_to_sample: 20_000, ..test_config() };
    let run = proto::RunId::new("it-refused").expect("run id");
    let bus = node::Bus::open(run, NodeId { role: Role::Replay, id: 0 }, &node::BusConfig::default())
        .await
        .expect("bus");
    let (_trigger, shutdown) = node::Shutdown::new();
    let error = within("run to refuse", replay_server::run(cfg, bus, shutdown)).await.unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("min_size_to_sample (20000) exceeds [replay] capacity_transitions (10000)"),
        "{message}"
    );
}
