//! Every run file in `deploy/configs/` and `deploy/experiments/` parses and validates for every role,
//! so an edit that breaks one fails here rather than when `deploy/local.sh` or `table.sh` starts it.

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
    assert_eq!((learner.hierarchy.depth(), executor.hierarchy.depth(), param.hierarchy.depth()), (1, 1, 1));
    // A key the table sets wins over the level-above default.
    let scaled = text.replace("scale_reward = 3.0", "scale_reward = 7.0");
    assert_eq!(role_config::<learner::LearnerConfig>(&scaled)?.agent.scale_reward, 7.0);
    Ok(())
}
