//! Restarted peers: a learner restarted from its checkpoint resumes at the same global step while
//! executors wait for it; a replay server restarted empty starves the learner while executors wait
//! at the barrier (a deadlock), which the param server breaks with a fresh warm-up share.

use cluster::{Cluster, Spec};
use proto::{BarrierReport, topics};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_restarted_learner_resumes_and_an_empty_replay_is_refilled() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("restarts-{}", std::process::id()));
    let mut spec = Spec::tiny("cluster-restarts", 2);
    spec.config = spec
        .config
        .replace("[learner]", &format!("[learner]\ncheckpoint_dir = {:?}", dir.display().to_string()));
    let mut cluster = Cluster::start(spec).await?;
    cluster.wait_for_learner_step(150).await?;

    let old = cluster.restart_learner().await?;
    assert!(old.updater.checkpoints >= 1, "the stopping learner writes a checkpoint: {:?}", old.updater);
    let resumed = cluster.wait_for_learner_step(old.updater.final_step + 100).await?;

    // The deadlock needs executors at the barrier when the replay server empties; were they behind
    // the learner instead, their next transitions would refill it without any help.
    let barrier = cluster.collect::<BarrierReport>(&topics::control_barrier_all(cluster.run())).await?;
    barrier
        .wait_until("both executors at the barrier", |rs| {
            (0..2).all(|id| {
                rs.iter()
                    .rev()
                    .find(|r| r.executor_id == id)
                    .is_some_and(|r| r.blocked && r.env_steps >= r.allowed_env_steps)
            })
        })
        .await?;
    let before = cluster.restart_replay().await?;
    assert!(before.size_transitions >= 200);
    // Empty now: the learner can only move on once executors, unblocked by a refill, store 200 again.
    cluster.wait_for_learner_step(resumed + 100).await?;

    let reports = cluster.stop().await?;
    assert_eq!(reports.learner.updater.start_step, old.updater.final_step, "resumed at the same global step");
    assert!(reports.param.counts.refills >= 1, "{:?}", reports.param.counts);
    assert!(reports.replay.counters.inserted_transitions >= 200);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
