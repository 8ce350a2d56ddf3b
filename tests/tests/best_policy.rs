//! The learner keeps its best-evaluated weights beside its checkpoints (`learner/src/best.rs`):
//! after a short tiny run on the real Ant, `best-policy.toml` holds the highest evaluation the
//! learner reported and `best-policy.safetensors` is a policy that acts.

use std::time::Duration;

use agent::{Actor, AgentConfig, Mode, ParamSnapshot};
use cluster::{Cluster, Spec, within};
use proto::{EvalReport, topics};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_learner_keeps_the_best_evaluated_weights() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("best-policy-cluster-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let checkpoints = dir.join("checkpoints");
    let config = Spec::tiny("best-policy", 1).config.replace(
        "[learner]",
        &format!("[learner]\ncheckpoint_dir = {:?}", checkpoints.display().to_string()),
    );
    let cluster = Cluster::start(Spec { run_id: "best-policy".into(), executors: 1, config }).await?;
    let evals = cluster.collect::<EvalReport>(&topics::evaluation(cluster.run())).await?;
    evals.wait_until("three evaluations", |e| e.len() >= 3).await?;
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;

    let reported = &stopped.learner.evaluations;
    assert!(reported.len() >= 3, "{} evaluations reported", reported.len());
    let best = *learner::BestPolicy::open(&checkpoints).best().expect("best-policy.toml readable");
    // The highest the learner reported, or one it finished while stopping (and so did not report).
    let highest = reported.iter().map(|e| e.mean_return).fold(f64::NEG_INFINITY, f64::max);
    assert!(best.mean_return >= highest, "kept {} below the reported {highest}", best.mean_return);
    if let Some(same) = reported.iter().find(|e| e.learner_step == best.learner_step) {
        assert_eq!(same, &best);
    }

    // The file is the trained policy in the weights format: it loads and acts.
    let weights = std::fs::read(checkpoints.join("best-policy.safetensors"))?;
    let snapshot = ParamSnapshot { version: best.learner_step, safetensors: weights };
    let cfg = AgentConfig {
        critic_hidden: vec![16],
        embedding_layers: vec![16, 4],
        coupling_hidden: vec![4],
        ..AgentConfig::for_task(105, 8)
    };
    let mut actor = Actor::new(cfg, 1)?;
    actor.load(&snapshot)?;
    let act = actor.act(&[0.1; 105], Mode::Deterministic)?;
    assert!(act.env_action.len() == 8 && act.env_action.iter().all(|a| a.is_finite() && a.abs() <= 1.0));
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}
