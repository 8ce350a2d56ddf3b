//! Deterministic mode (README "Deterministic mode"): the in-process cluster, run twice with the
//! same run file, ends with bit-identical learner parameters whatever the threads did (and, the
//! negative control, two normal-mode runs of the same run file do not); and a run stopped at a
//! checkpoint and resumed from every role's saved state ends as the uninterrupted run.

use std::io::Write;
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
    run_spec(Spec::tiny_deterministic(name, EXECUTORS, dir, max_updates), dir, max_updates).await
}

/// [`run`] in normal mode: the same run file (seed, networks, checkpoints, snapshot) with
/// `[train] deterministic = false`, so the learner samples whatever the executors have delivered.
async fn run_normal(name: &str, dir: &Path, max_updates: u64) -> Result<(Vec<u8>, Reports)> {
    let mut spec = Spec::tiny_deterministic(name, EXECUTORS, dir, max_updates);
    let on = "[train]\ndeterministic = true\n";
    assert!(spec.config.contains(on), "the deterministic run file turns the mode on where expected");
    spec.config = spec.config.replace(on, "[train]\ndeterministic = false\n");
    run_spec(spec, dir, max_updates).await
}

/// Runs `spec`, whose files are kept in `dir`, until `max_updates`; as [`run`].
async fn run_spec(spec: Spec, dir: &Path, max_updates: u64) -> Result<(Vec<u8>, Reports)> {
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

/// The negative control of the test above: the comparison can fail. In normal mode thread timing
/// decides what each sample holds, so the same run file ends with different parameters.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_normal_runs_end_with_different_parameters() -> Result<()> {
    // The variable overrides `[train] deterministic` for every role, this test's runs too.
    if std::env::var("SACLSP_DETERMINISTIC").is_ok_and(|value| value == "1") {
        // Past the test harness's capture, so that a passing run shows it.
        let _ = writeln!(
            std::io::stderr(),
            "skipped: SACLSP_DETERMINISTIC=1 puts every run in deterministic mode"
        );
        return Ok(());
    }
    let (a, b) = (folder("normal-a"), folder("normal-b"));
    // Half as far (normal mode's runs part from the first updates on), which keeps the pair about as
    // quick as a deterministic pair to 2,000.
    let (first, _) = run_normal("normal-a", &a, UPDATES / 2).await?;
    let (second, _) = run_normal("normal-b", &b, UPDATES / 2).await?;
    assert!(first != second, "two normal-mode runs ended with identical parameters");
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
