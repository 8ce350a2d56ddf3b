//! Deterministic mode (README "Deterministic mode"): the in-process cluster, run twice with the
//! same run file, ends with bit-identical learner parameters whatever the threads did; and a run
//! stopped at a checkpoint and resumed from every role's saved state ends as the uninterrupted run.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use cluster::{Cluster, Reports, Spec};

const EXECUTORS: u32 = 2;
const UPDATES: u64 = 2000;

/// A fresh folder for one run's checkpoints and snapshot.
fn folder(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Runs (or resumes) the deterministic run kept in `dir` until `max_updates`; returns the learner's
/// checkpoint at that step (every parameter, the Adam moments and the step) and the reports.
async fn run(name: &str, dir: &Path, max_updates: u64) -> Result<(Vec<u8>, Reports)> {
    let spec = Spec::tiny_deterministic(name, EXECUTORS, dir, max_updates);
    let reports = Cluster::start(spec).await?.finish().await?;
    assert_eq!(reports.learner.updater.final_step, max_updates);
    let checkpoints = learner::CheckpointDir::new(dir.join("checkpoints"));
    let last = checkpoints.at(max_updates)?.context("no checkpoint at max_updates")?;
    for (id, executor) in &reports.executors {
        assert!(executor.worker.env_steps > 0, "executor {id} stepped");
        assert_eq!(executor.rejected, Default::default(), "executor {id} rejected inputs");
    }
    assert_eq!(reports.replay.rejected, Default::default(), "the replay server rejected inputs");
    Ok((last.safetensors, reports))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_deterministic_runs_end_with_identical_parameters() -> Result<()> {
    let (a, b) = (folder("det-a"), folder("det-b"));
    let (first, _) = run("det-a", &a, UPDATES).await?;
    let (second, _) = run("det-b", &b, UPDATES).await?;
    // The runs' timing differs (both wait at every round, for whoever is slower), the result not.
    assert!(first == second, "the two runs' parameters differ");
    std::fs::remove_dir_all(a)?;
    std::fs::remove_dir_all(b)?;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_run_stopped_at_a_checkpoint_resumes_exactly() -> Result<()> {
    let (whole, parts) = (folder("det-whole"), folder("det-parts"));
    let (uninterrupted, _) = run("det-whole", &whole, UPDATES).await?;
    // Stop at 1,000 updates, then start every role again on the same folder.
    let (_, first) = run("det-parts", &parts, UPDATES / 2).await?;
    assert_eq!(first.learner.updater.start_step, 0);
    let (resumed, second) = run("det-parts", &parts, UPDATES).await?;
    assert_eq!(second.learner.updater.start_step, UPDATES / 2, "the learner resumed its checkpoint");
    assert!(second.replay.restored_sequence.is_some(), "the replay server restored its cut");
    assert!(resumed == uninterrupted, "the resumed run's parameters differ from the uninterrupted run's");
    std::fs::remove_dir_all(whole)?;
    std::fs::remove_dir_all(parts)?;
    Ok(())
}
