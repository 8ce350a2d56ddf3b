//! Every run file in `deploy/configs/` and `deploy/experiments/` parses and validates for every role,
//! and every role sizes its data the same (the task's widths), so an edit that breaks one fails here
//! rather than when `deploy/local.sh` or `table.sh` starts it.

use cluster::role_config;

#[test]
fn every_deploy_config_is_valid_for_every_role() -> anyhow::Result<()> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy");
    let mut checked = 0;
    let entries =
        std::fs::read_dir(root.join("configs"))?.chain(std::fs::read_dir(root.join("experiments"))?);
    for entry in entries {
        let path = entry?.path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path)?;
        let name = path.display();
        role_config::<replay_server::ReplayServerConfig>(&text).map_err(|e| e.context(format!("{name}")))?;
        role_config::<param_server::ParamServerConfig>(&text).map_err(|e| e.context(format!("{name}")))?;
        role_config::<learner::LearnerConfig>(&text).map_err(|e| e.context(format!("{name}")))?;
        role_config::<executor::ExecutorConfig>(&text).map_err(|e| e.context(format!("{name}")))?;
        widths_agree(&text).map_err(|e| e.context(format!("{name}")))?;
        checked += 1;
    }
    assert!(checked >= 11, "only {checked} run files in {}", root.display());
    Ok(())
}

#[test]
fn with_frozen_levels_every_role_trains_the_level_above_settings() -> anyhow::Result<()> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../deploy/experiments/rllab-2l-distributed.toml");
    // What table.sh appends; the file is read when the roles start, not when they parse.
    let text = std::fs::read_to_string(path)? + "\n[hierarchy]\nlevels = [\"low.safetensors\"]\n";
    let learner = role_config::<learner::LearnerConfig>(&text)?;
    let executor = role_config::<executor::ExecutorConfig>(&text)?;
    let param = role_config::<param_server::ParamServerConfig>(&text)?;
    for agent in [&learner.agent, &executor.agent, param.networks.as_ref().expect("[param_server] dims")] {
        assert!(!agent.squash && !agent.embedding_output_relu, "{agent:?}");
        assert_eq!(agent.scale_reward, 3.0);
    }
    assert_eq!(
        (learner.run.hierarchy.depth(), executor.run.hierarchy.depth(), param.hierarchy.depth()),
        (1, 1, 1)
    );
    // A key the table sets wins over the level-above default.
    let scaled = text.replace("scale_reward = 3.0", "scale_reward = 7.0");
    assert_eq!(role_config::<learner::LearnerConfig>(&scaled)?.agent.scale_reward, 7.0);
    Ok(())
}

/// Whether every role of a run file takes the task's widths (with HER, the goal-conditioned ones):
/// the learner's and the executors' networks, the replay server's rows, the param server's schema.
fn widths_agree(text: &str) -> anyhow::Result<()> {
    let learner = role_config::<learner::LearnerConfig>(text)?;
    let executor = role_config::<executor::ExecutorConfig>(text)?;
    let replay = role_config::<replay_server::ReplayServerConfig>(text)?;
    let param = role_config::<param_server::ParamServerConfig>(text)?;
    // The widths of the environment the executors step, built: not the run crate's table of them.
    let env = sim::her::make(&learner.run.her, learner.run.task, 0)?;
    let want = sim::Dims { obs_dim: env.spec().obs_dim, act_dim: env.spec().act_dim };
    let mut widths = vec![
        ("learner [agent]", learner.agent.obs_dim, learner.agent.act_dim),
        ("executor [agent]", executor.agent.obs_dim, executor.agent.act_dim),
        ("[replay_server]", replay.obs_dim as usize, replay.act_dim as usize),
    ];
    if let Some(networks) = &param.networks {
        widths.push(("[param_server] networks", networks.obs_dim, networks.act_dim));
    }
    for (table, obs, act) in widths {
        anyhow::ensure!(
            (obs, act) == (want.obs_dim, want.act_dim),
            "{table} has widths ({obs}, {act}), the task {} ({}, {})",
            learner.run.task,
            want.obs_dim,
            want.act_dim
        );
    }
    Ok(())
}

#[test]
fn a_run_file_cannot_give_a_role_other_widths() -> anyhow::Result<()> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/configs/inverted-pendulum.toml");
    let text = std::fs::read_to_string(path)?;
    widths_agree(&text)?;
    // Every role follows the task: switched to another task, every width follows.
    let ant = text.replace("task = \"inverted-pendulum\"", "task = \"ant-rllab\"");
    assert_ne!(ant, text);
    widths_agree(&ant)?;
    assert_eq!(role_config::<replay_server::ReplayServerConfig>(&ant)?.obs_dim, 125);
    // A width of a server's own would be a second source that could disagree: refused, named.
    for table in ["replay_server", "param_server"] {
        let own = text.replace(&format!("[{table}]\n"), &format!("[{table}]\nobs_dim = 4\n"));
        let own = if own == text { format!("{text}\n[{table}]\nobs_dim = 4\n") } else { own };
        let err = format!("{:#}", widths_agree(&own).unwrap_err());
        assert!(err.contains("obs_dim"), "{table}: {err}");
    }
    Ok(())
}
