//! The `SACLSP_*` environment variables: what a launcher (`deploy/local.sh`) sets so that every run
//! keeps its files in its own folder and picks its mode without editing the shared run file. Read
//! once, here; [`crate::RunSpec`] applies them.

use std::path::PathBuf;

/// Turns deterministic mode on (`1`) or off (anything else) whatever `[train] deterministic` says:
/// `deploy/local.sh` sets it for `DETERMINISTIC=1`.
pub const DETERMINISTIC_ENV: &str = "SACLSP_DETERMINISTIC";
/// Gives `[lockstep] executors` (the launcher knows how many it starts).
pub const EXECUTORS_ENV: &str = "SACLSP_EXECUTORS";
/// Overrides `[learner] checkpoint_dir`.
pub const CHECKPOINT_DIR_ENV: &str = "SACLSP_CHECKPOINT_DIR";
/// Overrides `[executor] spool_dir`.
pub const SPOOL_DIR_ENV: &str = "SACLSP_SPOOL_DIR";
/// Overrides `[replay_server] snapshot_path`.
pub const REPLAY_SNAPSHOT_ENV: &str = "SACLSP_REPLAY_SNAPSHOT";

/// The overrides in force, each `None` when its variable is unset.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Overrides {
    /// `SACLSP_DETERMINISTIC`: `Some(true)` for `1`.
    pub deterministic: Option<bool>,
    /// `SACLSP_EXECUTORS`, unparsed (a bad number is an error of the run file's reading).
    pub executors: Option<String>,
    /// `SACLSP_CHECKPOINT_DIR`.
    pub checkpoint_dir: Option<PathBuf>,
    /// `SACLSP_SPOOL_DIR`.
    pub spool_dir: Option<PathBuf>,
    /// `SACLSP_REPLAY_SNAPSHOT`.
    pub replay_snapshot: Option<PathBuf>,
}

impl Overrides {
    /// The variables of this process's environment.
    pub fn from_env() -> Overrides {
        let path = |name: &str| std::env::var_os(name).map(PathBuf::from);
        Overrides {
            deterministic: std::env::var(DETERMINISTIC_ENV).ok().map(|v| v == "1"),
            executors: std::env::var(EXECUTORS_ENV).ok(),
            checkpoint_dir: path(CHECKPOINT_DIR_ENV),
            spool_dir: path(SPOOL_DIR_ENV),
            replay_snapshot: path(REPLAY_SNAPSHOT_ENV),
        }
    }

    /// `SACLSP_EXECUTORS` as a number, checked.
    pub(crate) fn executors(&self) -> Result<Option<u32>, String> {
        self.executors
            .as_deref()
            .map(|n| n.parse().map_err(|e| format!("{EXECUTORS_ENV}={n}: {e}")))
            .transpose()
    }
}
