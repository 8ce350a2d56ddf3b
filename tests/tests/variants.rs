//! The dissertation's other two extensions as configurations of the same roles over the bus, tiny
//! networks on the real Ant (`docs/sac-lsp.md` §13-§14): a categorical critic (both variants) and
//! HER with speed goals each train for a few hundred updates, and every role accepts their frames.

use std::time::Duration;

use cluster::{Cluster, Spec, within};
use proto::{EvalReport, ExperienceBatch, topics};

/// What a short run published.
struct Trained {
    /// Executor 0's experience.
    experience: Vec<ExperienceBatch>,
    /// The learner's evaluations (the tiny run file evaluates every 100 updates).
    evals: Vec<EvalReport>,
}

/// Runs the tiny cluster with `config`, to `updates` learner updates and at least one evaluation,
/// and checks nobody refused anything.
async fn train(run_id: &str, config: String, updates: u64) -> anyhow::Result<Trained> {
    let cluster = Cluster::start(Spec { run_id: run_id.into(), executors: 1, config }).await?;
    let experience = cluster.collect::<ExperienceBatch>(&topics::experience(cluster.run(), 0)).await?;
    let evals = cluster.collect::<EvalReport>(&topics::evaluation(cluster.run())).await?;
    let step = cluster.wait_for_learner_step(updates).await?;
    evals.wait_until("an evaluation", |e| !e.is_empty()).await?;
    let stopped = within("the cluster to stop", Duration::from_secs(60), cluster.stop()).await??;
    assert!(stopped.learner.updater.final_step >= step);
    assert_eq!(stopped.learner.updater.non_finite_updates, 0);
    assert!(stopped.param.rejected.is_empty(), "{:?}", stopped.param.rejected);
    assert!(stopped.replay.counters.priorities_applied > 0);
    for (id, executor) in &stopped.executors {
        assert!(executor.rejected.is_empty(), "executor {id}: {:?}", executor.rejected);
        assert!(executor.worker.weights_loads >= 2, "executor {id} loaded new weights");
    }
    Ok(Trained { experience: experience.snapshot(), evals: evals.snapshot() })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn categorical_critics_train_over_the_bus() -> anyhow::Result<()> {
    for variant in ["soft_c51", "dissertation"] {
        let config = Spec::tiny("", 1).config.replace(
            "[agent]\n",
            &format!(
                "[agent]\ncritic = \"categorical\"\ncategorical = {{ variant = \"{variant}\", atoms = 11 }}\n"
            ),
        );
        let trained = train(&format!("categorical-{variant}"), config, 150).await?;
        assert!(trained.evals.iter().all(|e| e.goal_success.is_none()));
        assert!(trained.experience.iter().all(|b| b.td_errors.iter().all(|d| d.is_finite())));
    }
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn her_executors_publish_goal_conditioned_and_relabelled_experience() -> anyhow::Result<()> {
    // Speed goals on ant-v5: qvel (14 values) appended to the 105-d observation.
    let config = Spec::tiny("", 1)
        .config
        // Wider rows: the in-flight message bound grows with them.
        .replace("memory_budget_bytes = 268435456", "memory_budget_bytes = 536870912")
        + "\n[her]\ngoal = \"speed\"\nreward = \"binary\"\n";
    let trained = train("her-speed", config, 150).await?;
    // Evaluations report the goal success rate beside the task's own return.
    assert!(trained.evals.iter().all(|e| e.goal_success.is_some_and(|s| (0.0..=1.0).contains(&s))));
    let batches = trained.experience;
    let rewards: Vec<f32> = batches.iter().flat_map(|b| b.transitions.rewards.clone()).collect();
    assert!(batches.iter().all(|b| b.transitions.obs_dim == 119));
    // Binary goal rewards only, and relabelled goals (achieved later in the episode) are reached.
    assert!(rewards.iter().all(|r| *r == 0.0 || *r == -1.0), "{:?}", &rewards[..8]);
    assert!(rewards.contains(&0.0));
    // Each finished episode (60 steps at most here) adds k = 4 copies of its steps: after the
    // first batch seen, several times more transitions than env steps.
    let (first, rest) = batches.split_first().expect("experience");
    let env_steps = rest.iter().map(|b| b.env_steps).max().unwrap_or(0).saturating_sub(first.env_steps);
    let transitions = rest.iter().map(|b| b.transitions.len() as u64).sum::<u64>();
    assert!(env_steps >= 120, "only {env_steps} env steps seen");
    assert!(transitions > 2 * env_steps, "{transitions} transitions for {env_steps} env steps");
    Ok(())
}
