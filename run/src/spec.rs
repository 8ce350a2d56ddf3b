//! [`RunSpec`]: a run file read once. Every process of a run (the four roles, `sac-lsp train`,
//! `eval`, `render`) reads the same file through it, so the task, its widths, the seed, the
//! hierarchy, HER, deterministic mode and the `SACLSP_*` overrides mean the same thing everywhere.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::DeserializeOwned;

use crate::{Dims, HerConfig, Lockstep, Overrides, Task};

/// The `[train]` keys every process reads (the rest of the table belongs to the single-machine
/// loop, `sac-lsp train`, so unknown keys are ignored here).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default)]
pub struct TrainKeys {
    /// Task name (`ant-v5`, `ant-v5-xy`, `ant-rllab`, `inverted-pendulum`). Default `ant-v5`.
    pub task: String,
    /// The run's seed; every process derives its own streams from it. Default 1.
    pub seed: u64,
    /// Deterministic mode (`crate::lockstep`). Default false.
    pub deterministic: bool,
}

impl Default for TrainKeys {
    fn default() -> Self {
        Self { task: "ant-v5".into(), seed: 1, deterministic: false }
    }
}

/// The `[hierarchy]` table: a level trained on top of frozen, already trained levels (`docs/sac-lsp.md` §9).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HierarchyKeys {
    /// Checkpoints (or weights snapshots) of the frozen levels, bottom (env-facing) first. Empty (the
    /// default): a single-level run. The learner and the param server read these files; executors
    /// receive the levels over the bus, so only their host needs them.
    pub levels: Vec<PathBuf>,
}

impl HierarchyKeys {
    /// Number of frozen levels below the trained one.
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// Reads every level's file, bottom first; the error names the file.
    pub fn read(&self) -> Result<Vec<Vec<u8>>, String> {
        self.levels
            .iter()
            .map(|path| {
                std::fs::read(path).map_err(|e| format!("[hierarchy] levels: {}: {e}", path.display()))
            })
            .collect()
    }
}

/// Why a run file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The file could not be read.
    #[error("cannot read run file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML, a table does not match its struct, or a value is out of range.
    #[error("run file {path}: {message}")]
    Invalid {
        /// The file (`<defaults>` without one).
        path: String,
        /// What is wrong, naming the table.
        message: String,
    },
}

/// A run file, parsed once: the tables every process shares, typed and checked, the overrides
/// applied, and the document for the tables of one crate ([`RunSpec::table`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// The file it was read from (`None`: no file, every default).
    pub path: Option<PathBuf>,
    /// `[train]`'s shared keys (`deterministic` with `SACLSP_DETERMINISTIC` applied).
    pub train: TrainKeys,
    /// The task `[train] task` names.
    pub task: Task,
    /// `[her]`: goals appended to the observation, goal rewards, relabelled episodes.
    pub her: HerConfig,
    /// `[hierarchy]`: frozen levels below the trained one.
    pub hierarchy: HierarchyKeys,
    /// Deterministic mode's schedule (`[train] deterministic`, `[lockstep]`); `None` otherwise.
    pub lockstep: Option<Lockstep>,
    /// The `SACLSP_*` overrides in force; each crate's config applies the ones of its keys.
    pub overrides: Overrides,
    document: toml::Table,
}

impl Default for RunSpec {
    /// Every table's defaults, no overrides.
    fn default() -> Self {
        Self::parse_with("", &Overrides::default())
            .unwrap_or_else(|e| unreachable!("the defaults are valid: {e}"))
    }
}

impl RunSpec {
    /// Reads `path` (every default without one) with this process's `SACLSP_*` overrides.
    pub fn load(path: Option<&Path>) -> Result<RunSpec, RunError> {
        let text = match path {
            Some(path) => std::fs::read_to_string(path)
                .map_err(|source| RunError::Read { path: path.to_path_buf(), source })?,
            None => String::new(),
        };
        let mut spec = Self::parse(&text).map_err(|message| RunError::Invalid {
            path: path.map_or_else(|| "<defaults>".into(), |p| p.display().to_string()),
            message,
        })?;
        spec.path = path.map(Path::to_path_buf);
        Ok(spec)
    }

    /// Parses a run file's text with this process's `SACLSP_*` overrides.
    pub fn parse(text: &str) -> Result<RunSpec, String> {
        Self::parse_with(text, &Overrides::from_env())
    }

    /// Parses a run file's text with the given overrides; the error names the table.
    pub fn parse_with(text: &str, overrides: &Overrides) -> Result<RunSpec, String> {
        let document: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
        if document.contains_key("replay_server")
            && text.lines().any(|l| l.trim_start().starts_with("[replay_server.buffer]"))
        {
            return Err("[replay_server.buffer] is now [replay]: one table holds the buffer's settings for \
                        single-machine and distributed runs"
                .into());
        }
        let mut train: TrainKeys = crate::table::table(&document, "train")?;
        if let Some(on) = overrides.deterministic {
            train.deterministic = on;
        }
        let task: Task = train.task.parse().map_err(|e| format!("[train] task: {e}"))?;
        let her: HerConfig = crate::table::table(&document, "her")?;
        // The goal must fit the task before any width is computed from it; n_step is the agent's
        // and checked with it (`HerConfig::validate`).
        her.slice(task)?;
        let hierarchy: HierarchyKeys = crate::table::table(&document, "hierarchy")?;
        let lockstep = Lockstep::from_document(&document, train.deterministic, overrides.executors()?)?;
        Ok(RunSpec {
            path: None,
            train,
            task,
            her,
            hierarchy,
            lockstep,
            overrides: overrides.clone(),
            document,
        })
    }

    /// The widths the networks and the replay see: the task's observation (with HER, the goal
    /// appended) and action.
    pub fn dims(&self) -> Dims {
        self.her.dims(self.task)
    }

    /// The run's seed.
    pub fn seed(&self) -> u64 {
        self.train.seed
    }

    /// Table `name` (one crate's own), over `T`'s defaults; the error names the table.
    pub fn table<T: DeserializeOwned + Default>(&self, name: &str) -> Result<T, String> {
        crate::table::table(&self.document, name)
    }

    /// Table `name` over `base` instead of `T::default()` (see [`crate::table::table_over`]).
    pub fn table_over<T: serde::Serialize + DeserializeOwned>(
        &self,
        name: &str,
        base: &T,
    ) -> Result<T, String> {
        crate::table::table_over(&self.document, name, base)
    }
}

/// A crate's configuration: its table name, how it is read from a run, and a check with exact
/// messages.
pub trait RoleConfig: Sized + Default {
    /// The TOML table this config lives in.
    const SECTION: &'static str;

    /// Checks every value; the message names the offending key.
    fn validate(&self) -> Result<(), String>;

    /// The config of a run: by default its own table (defaults when missing). Configs that also
    /// need the shared tables (`[agent]`, the task) read them from `spec`.
    fn from_spec(spec: &RunSpec) -> Result<Self, String>;

    /// Parses and reads a run file's text (tests, and callers that hold the text).
    fn parse(text: &str) -> Result<Self, String> {
        Self::from_spec(&RunSpec::parse(text)?)
    }

    /// Loads `path` (defaults without one) and validates the config; the error names the file.
    fn load(path: Option<&Path>) -> Result<Self, RunError> {
        let spec = RunSpec::load(path)?;
        let invalid = |message| RunError::Invalid {
            path: path.map_or_else(|| "<defaults>".into(), |p| p.display().to_string()),
            message,
        };
        let config = Self::from_spec(&spec).map_err(invalid)?;
        config.validate().map_err(invalid)?;
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::GoalKind;

    fn spec(text: &str) -> Result<RunSpec, String> {
        RunSpec::parse_with(text, &Overrides::default())
    }

    #[test]
    fn shared_tables_are_read_once_with_their_defaults() {
        let s = spec("").unwrap();
        assert_eq!(s, RunSpec::default());
        assert_eq!((s.task, s.seed(), s.lockstep), (Task::AntV5, 1, None));
        assert_eq!(s.dims(), Dims { obs_dim: 105, act_dim: 8 });
        let her = spec("[train]\ntask = \"ant-rllab\"\nepochs = 3\n[her]\ngoal = \"speed\"\n").unwrap();
        assert_eq!(her.her.goal, GoalKind::Speed);
        assert_eq!(her.dims(), Dims { obs_dim: 125 + 14, act_dim: 8 }, "the goal widens the input");
        let h = spec("[hierarchy]\nlevels = [\"a\", \"b\"]\n").unwrap();
        assert_eq!(h.hierarchy.depth(), 2);
        assert!(h.hierarchy.read().unwrap_err().contains("a:"), "the missing file is named");
    }

    #[test]
    fn bad_tables_are_named() {
        assert!(spec("[train]\ntask = \"ant-v9\"\n").unwrap_err().contains("[train] task"));
        assert!(spec("[her]\ngoal = \"speeed\"\n").unwrap_err().starts_with("[her]"));
        assert!(
            spec("[train]\ntask = \"ant-v5\"\n[her]\ngoal = \"position\"\n")
                .unwrap_err()
                .contains("ant-v5-xy")
        );
        assert!(spec("[hierarchy]\nlevel = []\n").unwrap_err().starts_with("[hierarchy]"));
        assert!(spec("[replay_server.buffer]\ncapacity = 3\n").unwrap_err().contains("is now [replay]"));
        assert!(spec("not toml").is_err());
    }

    #[test]
    fn overrides_apply_once() {
        let on = Overrides { deterministic: Some(true), executors: Some("3".into()), ..Overrides::default() };
        let s = RunSpec::parse_with("", &on).unwrap();
        assert!(s.train.deterministic);
        assert_eq!(s.lockstep.unwrap().executors, 3);
        let off = Overrides { deterministic: Some(false), ..Overrides::default() };
        let text = "[train]\ndeterministic = true\n[lockstep]\nexecutors = 2\n";
        assert_eq!(RunSpec::parse_with(text, &off).unwrap().lockstep, None);
        assert!(spec(text).unwrap().lockstep.is_some());
        let bad = Overrides { executors: Some("x".into()), ..on };
        assert!(RunSpec::parse_with("", &bad).unwrap_err().contains("SACLSP_EXECUTORS=x"));
    }
}
