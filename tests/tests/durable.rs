//! Durable experience over the bus: the replay server is killed mid-run (no final snapshot) and
//! restarted from its last periodic snapshot; executors send their spools again, and every batch
//! they produced is accounted for: stored once, or dropped with a reason, never lost. An executor
//! killed mid-run loses what it held in memory, and its made marks count exactly that.

use cluster::audit::audit;
use cluster::{Cluster, Spec};
use proto::{DurableMarks, topics};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_killed_replay_server_loses_no_transition() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("durable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (spec, spools) = Spec::tiny_durable("cluster-durable", 2, &dir);
    let mut cluster = Cluster::start(spec).await?;
    let marks = cluster.collect::<DurableMarks>(&topics::replay_durable(cluster.run())).await?;
    cluster.wait_for_learner_step(100).await?;
    // A durable snapshot that holds both executors' batches, then more inserted after it.
    marks
        .wait_until("a snapshot holding both executors' batches", |m| {
            m.last().is_some_and(|m| {
                (0..2).all(|id| m.marks.iter().any(|k| k.executor_id == id && k.durable_below > 0))
            })
        })
        .await?;
    let step = cluster.wait_for_learner_step(150).await?;

    cluster.kill_replay().await?;
    // Executors keep producing into their spools until the barrier stops them; then a new server
    // restores the snapshot and they send what it does not hold.
    cluster.start_replay().await?;
    cluster.wait_for_learner_step(step + 150).await?;

    let reports = cluster.stop().await?;
    let replay = &reports.replay;
    assert!(replay.restored_sequence.is_some(), "the second server started from the snapshot");
    let audit = audit(&spools, 0..2, &replay.streams)?;
    audit.check().map_err(anyhow::Error::msg)?;
    assert_eq!(audit.pending, 0, "executors stopped before the replay server: all arrived: {audit:?}");
    assert_eq!(audit.lost_at_kill, 0, "executors stopped cleanly: nothing left in memory: {audit:?}");
    assert!(audit.dropped.is_empty() && audit.refused == 0, "{audit:?}");
    assert_eq!(audit.stored, audit.produced);
    // Every stored transition once: the restored counter plus what arrived after equals the ledgers.
    assert_eq!(replay.counters.inserted_transitions, audit.produced, "{audit:?} {:?}", replay.counters);
    let made: u64 = reports.executors.values().map(|e| e.worker.transitions).sum();
    assert_eq!(made, audit.produced, "the made marks count what the rollouts made: {audit:?}");
    let resent: u64 = reports.executors.values().filter_map(|e| e.spool).map(|s| s.resent_batches).sum();
    assert!(resent > 0, "executors sent their spools again: {:?}", reports.executors);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// Executor 1 is killed mid-run (its task aborted: the rollout's pending transitions and the batches
/// queued for the spool go with it) and started again on the same spool. The audit explains every
/// transition: what its ledger names is stored, and what the killed process held in memory is the
/// difference between its stream's made mark and its ledger, within what an executor can hold.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_killed_executors_transitions_in_memory_are_counted() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("durable-kill-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (spec, spools) = Spec::tiny_durable("cluster-durable-kill", 2, &dir);
    let mut cluster = Cluster::start(spec).await?;
    let step = cluster.wait_for_learner_step(100).await?;
    cluster.kill_executor(1).await?;
    cluster.start_executor(1).await?;
    cluster.wait_for_learner_step(step + 150).await?;

    let reports = cluster.stop().await?;
    let audit = audit(&spools, 0..2, &reports.replay.streams)?;
    audit.check().map_err(anyhow::Error::msg)?;
    assert_eq!(audit.stored + audit.lost_at_kill, audit.produced, "{audit:?}");
    assert_eq!(reports.replay.counters.inserted_transitions, audit.stored, "{audit:?}");
    assert!(audit.killed_streams <= 1, "only the killed process's stream: {audit:?}");
    // tiny.toml: 16 transitions a batch, one per step (no HER, 1-step returns).
    let bound = (executor::OUT_QUEUE as u64 + 2) * 16 + 1;
    assert!(audit.lost_at_kill <= bound, "{audit:?}");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
