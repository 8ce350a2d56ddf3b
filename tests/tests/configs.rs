//! Every run file in `deploy/configs/` parses and validates for every role, so an edit that breaks
//! one fails here rather than when `deploy/local.sh` starts the role.

use cluster::role_config;

#[test]
fn every_deploy_config_is_valid_for_every_role() -> anyhow::Result<()> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/configs");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir)? {
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
    assert!(checked >= 3, "only {checked} run files in {}", dir.display());
    Ok(())
}
