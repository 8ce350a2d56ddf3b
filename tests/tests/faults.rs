//! Message loss and reordering, made on purpose with the harness's per-topic faults (every role's bus
//! passes its messages through them): the cases that were found and fixed by hand before, each now
//! made to happen instead of waited for.

use std::time::{Duration, Instant};

use cluster::audit::audit;
use cluster::{Cluster, Network, Spec, within};
use node::Direction;
use proto::{DurableMarks, GlobalStep, Role, Topic, topics};

/// The first weights the learner sends are lost on the way to the param server (after it listens, so
/// no "someone started listening" re-send comes). Executors wait for their first weights and the
/// learner has no data to make newer ones: only the learner noticing that the param server still
/// announces no weights, and sending them again, gets the run going.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_lost_weights_frame_is_sent_again() -> anyhow::Result<()> {
    let network = Network::default();
    let param = network.of(Role::Param, 0);
    param.drop_next(Direction::In, |t| *t == Topic::ParamsPublish, 1);
    let cluster = Cluster::start_with(Spec::tiny("faults-weights", 2), network).await?;
    cluster.wait_for_learner_step(100).await?;
    assert_eq!(param.dropped(), 1, "the first weights frame was lost");
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;
    assert!(stopped.learner.weights_resent >= 1, "{:?}", stopped.learner);
    Ok(())
}

/// Every weights push of the param server is lost (a host whose router drops them): executors
/// still take each newer version, by asking for it once its push is overdue.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn lost_weight_pushes_are_asked_for() -> anyhow::Result<()> {
    let network = Network::default();
    let param = network.of(Role::Param, 0);
    param.cut(Direction::Out, |t| *t == Topic::ParamsStream);
    let cluster = Cluster::start_with(Spec::tiny("faults-push", 2), network).await?;
    let reports =
        cluster.collect::<proto::BarrierReport>(&topics::control_barrier_all(cluster.run())).await?;
    cluster.wait_for_learner_step(100).await?;
    reports
        .wait_until("both executors to act with weights newer than their first", |rs| {
            (0..2).all(|id| {
                let mine = || rs.iter().filter(|r| r.executor_id == id);
                let first = mine().map(|r| r.weights_version).min();
                mine().any(|r| Some(r.weights_version) > first)
            })
        })
        .await?;
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;
    assert!(param.dropped() >= 1, "pushes were made and lost");
    assert!(stopped.param.counts.weights_pushed >= 1, "{:?}", stopped.param.counts);
    for (id, executor) in &stopped.executors {
        assert_eq!(executor.weights.pushed, 0, "executor {id}: {:?}", executor.weights);
        assert!(executor.weights.asked >= 2, "executor {id} asked for newer weights: {:?}", executor.weights);
    }
    Ok(())
}

/// Executor 1's barrier reports reach the param server late (300 ms), so after it dies its last
/// reports arrive once its liveliness token is gone: they are counted as from an unknown executor and
/// do not bring it back to life (a revived ghost would hold the barrier's shares).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_late_report_from_a_dead_executor_does_not_revive_it() -> anyhow::Result<()> {
    let network = Network::default();
    let param = network.of(Role::Param, 0);
    let delay = Duration::from_millis(300);
    param.delay(Direction::In, |t| *t == Topic::ControlBarrier { executor_id: 1 }, delay);
    let mut cluster = Cluster::start_with(Spec::tiny("faults-ghost", 2), network).await?;
    let steps = cluster.collect::<GlobalStep>(&topics::control_step(cluster.run())).await?;
    cluster.wait_for_learner_step(100).await?;
    // Announcements before the kill (at start, executor 1 joins after executor 0) do not count.
    let before_kill = steps.snapshot().len();
    cluster.kill_executor(1).await?;
    let dropped = cluster.wait_for_global_step("executor 1 to be dropped", |s| s.live_executors == 1).await?;
    // Its held reports land within a few delays of its death; the survivor goes on meanwhile.
    let since = Instant::now();
    cluster.wait_for_learner_step(dropped.learner_step + 100).await?;
    within("a few report delays to pass", Duration::from_secs(30), async {
        while since.elapsed() < delay * 4 {
            tokio::time::sleep(delay).await;
        }
    })
    .await?;
    let announced = steps.snapshot();
    let after = announced.iter().skip(before_kill).skip_while(|s| s.live_executors != 1);
    assert!(after.clone().all(|s| s.live_executors == 1), "a dead executor came back: {announced:?}");
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;
    assert!(param.delayed() > 0);
    assert!(
        stopped.param.counts.reports_from_unknown >= 1,
        "no late report arrived: {:?}",
        stopped.param.counts
    );
    Ok(())
}

/// With durable experience, one batch of executor 0 is lost on the way to the replay server, which
/// stays up. The stream's durable prefix stops at the hole; once it has not moved across two
/// snapshots the executor sends that batch again, the prefix moves past it, and the audit finds every
/// produced transition stored once.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_lost_experience_batch_is_sent_again() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("faults-batch-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (spec, spools) = Spec::tiny_durable("faults-batch", 2, &dir);
    let network = Network::default();
    let replay = network.of(Role::Replay, 0);
    // The fifth batch executor 0 sends (seq 4) never arrives.
    const LOST_SEQ: u64 = 4;
    let seen = std::sync::atomic::AtomicU64::new(0);
    replay.drop_next(
        Direction::In,
        move |t| {
            matches!(t, Topic::Experience { executor_id: 0 })
                && seen.fetch_add(1, std::sync::atomic::Ordering::Relaxed) == LOST_SEQ
        },
        1,
    );
    let cluster = Cluster::start_with(spec, network).await?;
    let marks = cluster.collect::<DurableMarks>(&topics::replay_durable(cluster.run())).await?;
    marks
        .wait_until("executor 0's durable prefix to pass the lost batch", |m| {
            m.last().is_some_and(|m| m.marks.iter().any(|k| k.executor_id == 0 && k.durable_below > LOST_SEQ))
        })
        .await?;
    assert_eq!(replay.dropped(), 1, "one batch was lost");
    let reports = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;
    let audit = audit(&spools, 0..2, &reports.replay.streams)?;
    assert_eq!((audit.lost, audit.pending), (0, 0), "{audit:?}");
    assert_eq!(audit.stored, audit.produced, "{audit:?}");
    assert_eq!(reports.replay.counters.inserted_transitions, audit.produced, "stored once: {audit:?}");
    let resent = reports.executors.get(&0).and_then(|e| e.spool).map_or(0, |s| s.resent_batches);
    assert!(resent >= 1, "executor 0 sent the lost batch again: {:?}", reports.executors.get(&0));
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
