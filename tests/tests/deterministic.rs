//! Deterministic mode (README "Deterministic mode"): the in-process cluster, run twice with the
//! same run file, ends with bit-identical learner parameters, whatever the threads did.

use anyhow::{Context, Result};
use cluster::{Cluster, Spec};

const EXECUTORS: u32 = 2;
const UPDATES: u64 = 2000;

/// One deterministic run to `UPDATES`; returns the learner's final checkpoint (every parameter,
/// the Adam moments and the step) and the reports.
async fn run(name: &str) -> Result<(Vec<u8>, cluster::Reports)> {
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let spec = Spec::tiny_deterministic(name, EXECUTORS, &dir, UPDATES);
    let reports = Cluster::start(spec).await?.finish().await?;
    let checkpoints = learner::CheckpointDir::new(dir.join("checkpoints"));
    let last = checkpoints.latest()?.context("no checkpoint written")?;
    assert_eq!(last.step, UPDATES);
    std::fs::remove_dir_all(&dir)?;
    Ok((last.safetensors, reports))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_deterministic_runs_end_with_identical_parameters() -> Result<()> {
    let (first, a) = run("det-a").await?;
    let (second, _) = run("det-b").await?;
    assert_eq!(a.learner.updater.final_step, UPDATES);
    // The runs' timing differs (both wait at every round, for whoever is slower), the result not.
    assert!(first == second, "the two runs' parameters differ");
    for (id, executor) in &a.executors {
        assert!(executor.worker.env_steps > 0, "executor {id} stepped");
        assert_eq!(executor.rejected, Default::default(), "executor {id} rejected inputs");
    }
    assert_eq!(a.replay.rejected, Default::default(), "the replay server rejected inputs");
    Ok(())
}
