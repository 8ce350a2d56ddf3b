//! Per-crate configuration tables: one TOML file per run, one table per crate (`[replay_server]`,
//! `[learner]`, `[agent]`, ...). A missing table means the crate's documented defaults; an unknown key
//! is an error (the structs use `deny_unknown_fields`), so a typo never silently runs the default.

use std::path::{Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::NodeError;

/// A crate's configuration: its table name, defaults, and a check with exact messages.
pub trait RoleConfig: DeserializeOwned + Default {
    /// The TOML table this config lives in.
    const SECTION: &'static str;

    /// Checks every value; the message names the offending key.
    fn validate(&self) -> Result<(), String>;

    /// Reads the config from a whole run file: by default its own table (defaults when it is
    /// missing). Roles that also need shared tables (`[agent]`, the task) override this.
    fn parse(text: &str) -> Result<Self, String> {
        parse_section(text, Self::SECTION)
    }
}

/// The `[train]` keys every distributed role that simulates or trains reads (the rest of the table
/// belongs to the single-machine loop, so unknown keys are ignored here).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(default)]
pub struct RunKeys {
    /// Task name (`ant-v5`, `ant-rllab`, `inverted-pendulum`). Default `ant-v5`.
    pub task: String,
    /// The run's seed; every process derives its own streams from it.
    pub seed: u64,
}

impl Default for RunKeys {
    fn default() -> Self {
        Self { task: "ant-v5".into(), seed: 1 }
    }
}

/// The `[hierarchy]` table: a level trained on top of frozen, already trained levels (`docs/sac-lsp.md` §9).
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
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

/// Deserializes table `section` over `base`: keys the table sets replace `base`'s values, the
/// others keep them (unknown keys are still errors). So a run file can start a config from
/// defaults other than `T::default()`, such as the level-above settings of a hierarchy's top level.
pub fn parse_section_over<T: Serialize + DeserializeOwned>(
    text: &str,
    section: &str,
    base: &T,
) -> Result<T, String> {
    let mut document: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    let mut merged = toml::Table::try_from(base).map_err(|e| e.to_string())?;
    match document.remove(section) {
        Some(toml::Value::Table(table)) => merged.extend(table),
        Some(_) => return Err(format!("{section} is not a table")),
        None => {}
    }
    merged.try_into().map_err(|e: toml::de::Error| e.to_string())
}

/// A seed of stream `id` of a run seeded `seed`: distinct, well-mixed streams per id (splitmix64).
pub fn mix_seed(seed: u64, id: u32) -> u64 {
    let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15u64.wrapping_mul(u64::from(id) + 1));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The first `(key, value)` whose value is 0, for "must be > 0" checks in `validate()`.
pub fn first_zero<'a>(values: &[(&'a str, u64)]) -> Option<&'a str> {
    values.iter().find(|(_, v)| *v == 0).map(|(key, _)| *key)
}

/// Loads and validates `T`'s table from `path` (defaults when there is no file or no table).
pub fn load<T: RoleConfig>(path: Option<&Path>) -> Result<T, NodeError> {
    let config = match path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|source| NodeError::ConfigRead { path: path.to_path_buf(), source })?;
            T::parse(&text).map_err(|message| NodeError::ConfigParse {
                path: path.to_path_buf(),
                section: T::SECTION.to_string(),
                message,
            })?
        }
        None => T::default(),
    };
    config
        .validate()
        .map_err(|message| NodeError::ConfigInvalid { section: T::SECTION.to_string(), message })?;
    Ok(config)
}

/// Deserializes one table of a TOML document; a missing table gives the defaults.
pub fn parse_section<T: DeserializeOwned + Default>(text: &str, section: &str) -> Result<T, String> {
    let mut document: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    match document.remove(section) {
        Some(value) => value.try_into().map_err(|e: toml::de::Error| e.to_string()),
        None => Ok(T::default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(default, deny_unknown_fields)]
    struct Example {
        batch_size: u32,
        name: String,
    }

    impl Default for Example {
        fn default() -> Self {
            Self { batch_size: 128, name: "x".into() }
        }
    }

    #[test]
    fn a_table_overrides_defaults_and_a_missing_table_keeps_them() {
        let text = "[example]\nbatch_size = 64\n[other]\nanything = 1\n";
        let e: Example = parse_section(text, "example").unwrap();
        assert_eq!(e, Example { batch_size: 64, name: "x".into() });
        let d: Example = parse_section(text, "missing").unwrap();
        assert_eq!(d, Example::default());
    }

    #[test]
    fn a_table_over_a_base_keeps_the_keys_it_does_not_set() {
        #[derive(Debug, Deserialize, serde::Serialize, PartialEq, Default)]
        #[serde(default, deny_unknown_fields)]
        struct Settings {
            scale: f64,
            squash: bool,
            label: Option<String>,
        }
        let base = Settings { scale: 3.0, squash: false, label: None };
        let over: Settings = parse_section_over("[s]\nsquash = true\n", "s", &base).unwrap();
        assert_eq!(over, Settings { scale: 3.0, squash: true, label: None });
        let none: Settings = parse_section_over("", "s", &base).unwrap();
        assert_eq!(none, base);
        assert!(
            parse_section_over::<Settings>("[s]\nsqash = true\n", "s", &base).unwrap_err().contains("sqash")
        );
        let hierarchy: HierarchyKeys =
            parse_section("[hierarchy]\nlevels = [\"a\", \"b\"]\n", "hierarchy").unwrap();
        assert_eq!(hierarchy.depth(), 2);
        assert!(hierarchy.read().unwrap_err().contains("a:"), "the missing file is named");
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_errors() {
        let err = parse_section::<Example>("[example]\nbatch_sise = 64\n", "example").unwrap_err();
        assert!(err.contains("batch_sise"), "{err}");
        assert!(parse_section::<Example>("[example]\nbatch_size = \"a\"\n", "example").is_err());
    }
}
