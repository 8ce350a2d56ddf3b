//! A 2-level hierarchy across the roles (`docs/sac-lsp.md` §9), tiny networks on the real Ant: the param
//! server
//! serves the frozen level, executors act through it and store the trained level's latents h,
//! the learner trains only the top level and embeds the frozen one in its checkpoints, and an
//! executor that joins late, with no file of the frozen level, receives it over the bus.

use std::time::Duration;

use agent::{Actor, AgentConfig, Batch, Learner, Mode, ParamSnapshot, PolicyStack};
use cluster::{Cluster, Spec, within};
use proto::{ExperienceBatch, WeightsSnapshot, topics};

/// A trained (a few updates) tiny Ant level with the tiny run file's networks, as a checkpoint file.
fn low_level(dir: &std::path::Path) -> anyhow::Result<std::path::PathBuf> {
    let cfg = AgentConfig {
        critic_hidden: vec![16],
        embedding_layers: vec![16, 4],
        coupling_hidden: vec![4],
        batch_size: 8,
        ..AgentConfig::for_task(105, 8)
    };
    let mut learner = Learner::new(cfg.clone(), 11)?;
    let n = cfg.batch_size;
    let batch = Batch {
        size: n,
        observations: (0..n * 105).map(|i| ((i % 17) as f32 - 8.0) / 8.0).collect(),
        actions: (0..n * 8).map(|i| ((i % 7) as f32 - 3.0) / 4.0).collect(),
        rewards: (0..n).map(|i| i as f32 / 4.0).collect(),
        next_observations: (0..n * 105).map(|i| ((i % 13) as f32 - 6.0) / 6.0).collect(),
        terminated: vec![0.0; n],
        ..Batch::default()
    };
    for _ in 0..3 {
        learner.update(&batch)?;
    }
    let path = dir.join("low-level.safetensors");
    std::fs::write(&path, learner.checkpoint()?.safetensors)?;
    Ok(path)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_second_level_trains_on_a_frozen_one_served_over_the_bus() -> anyhow::Result<()> {
    let dir = std::env::temp_dir().join(format!("hierarchy-cluster-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let low = low_level(&dir)?;
    let low_bytes = std::fs::read(&low)?;
    let frozen_hash = PolicyStack::from_weights(&[&low_bytes])?.content_hash()?;
    let checkpoints = dir.join("checkpoints");
    let config = Spec::tiny("hierarchy", 1).config.replace(
        "[learner]",
        &format!("[learner]\ncheckpoint_dir = {:?}", checkpoints.display().to_string()),
    ) + &format!("\n[hierarchy]\nlevels = [{:?}]\n", low.display().to_string());
    let mut cluster = Cluster::start(Spec { run_id: "hierarchy".into(), executors: 1, config }).await?;
    let weights = cluster.collect::<WeightsSnapshot>(&topics::params_publish(cluster.run())).await?;
    cluster.wait_for_learner_step(100).await?;

    // A late joiner: its files are irrelevant, the level comes from the param server.
    let late = cluster.collect::<ExperienceBatch>(&topics::experience(cluster.run(), 1)).await?;
    cluster.start_executor(1).await?;
    late.wait_until("the late executor's experience", |b| b.iter().map(|b| b.len()).sum::<usize>() >= 64)
        .await?;
    let step = cluster.wait_for_learner_step(200).await?;
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;

    // The trained level's actions are latents h (no squash): outside [-1, 1] now and then, which
    // a squashed env action never is.
    let actions: Vec<f32> = late.snapshot().iter().flat_map(|b| b.transitions.actions.clone()).collect();
    assert!(actions.iter().any(|a| a.abs() > 1.0), "replay holds squashed actions: {:?}", &actions[..8]);
    // Every weights frame names the frozen level, and nobody refused one.
    let frames = weights.snapshot();
    assert!(!frames.is_empty() && frames.iter().all(|w| w.stack.map(|h| h.0) == Some(frozen_hash)));
    assert!(stopped.param.rejected.is_empty(), "{:?}", stopped.param.rejected);
    for (id, executor) in &stopped.executors {
        assert!(executor.rejected.is_empty(), "executor {id}: {:?}", executor.rejected);
        assert!(executor.worker.weights_loads >= 1 && executor.batches_published > 0, "executor {id}");
    }
    assert!(stopped.learner.updater.final_step >= step);

    // The final checkpoint carries the frozen level bit for bit, and acts through it.
    let newest = learner::CheckpointDir::new(&checkpoints).latest()?.expect("a final checkpoint");
    let tensors =
        ParamSnapshot { version: newest.step, safetensors: newest.safetensors.clone() }.tensors()?;
    let embedded = PolicyStack::from_embedded(&tensors)?;
    assert_eq!(embedded.content_hash()?, frozen_hash, "the frozen level changed");
    let original = ParamSnapshot { version: 0, safetensors: low_bytes }.tensors()?;
    for (name, t) in original.iter().filter(|(n, _)| n.starts_with("policy.")) {
        let kept = &tensors[&format!("frozen.0.{name}")];
        assert_eq!(kept.flatten_all()?.to_vec1::<f32>()?, t.flatten_all()?.to_vec1::<f32>()?, "{name}");
    }
    let top = AgentConfig {
        critic_hidden: vec![16],
        embedding_layers: vec![16, 4],
        coupling_hidden: vec![4],
        ..AgentConfig::default_at_level(1)
    };
    let mut actor = Actor::with_stack(AgentConfig { obs_dim: 105, act_dim: 8, ..top }, embedded, 1)?;
    actor.load(&ParamSnapshot { version: newest.step, safetensors: newest.safetensors })?;
    let act = actor.act(&[0.1; 105], Mode::Deterministic)?;
    assert!(act.env_action.iter().all(|a| a.abs() <= 1.0) && act.env_action != act.action);
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}
