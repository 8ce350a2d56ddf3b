//! Tables of a parsed run file, deserialized into typed structs. A missing table means the
//! struct's documented defaults; an unknown key is an error (the structs use `deny_unknown_fields`),
//! so a typo never silently runs the default.

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Deserializes table `name` of `document`; a missing table gives the defaults. The error names
/// the table.
pub fn table<T: DeserializeOwned + Default>(document: &toml::Table, name: &str) -> Result<T, String> {
    match document.get(name) {
        Some(value) => {
            value.clone().try_into().map_err(|e: toml::de::Error| format!("[{name}] {}", e.message()))
        }
        None => Ok(T::default()),
    }
}

/// Deserializes table `name` over `base`: keys the table sets replace `base`'s values, the others
/// keep them (unknown keys are still errors). So a run file can start a config from defaults other
/// than `T::default()`, such as the level-above settings of a hierarchy's top level.
pub fn table_over<T: Serialize + DeserializeOwned>(
    document: &toml::Table,
    name: &str,
    base: &T,
) -> Result<T, String> {
    let mut merged = toml::Table::try_from(base).map_err(|e| format!("[{name}] {e}"))?;
    match document.get(name) {
        Some(toml::Value::Table(table)) => merged.extend(table.clone()),
        Some(_) => return Err(format!("[{name}] is not a table")),
        None => {}
    }
    merged.try_into().map_err(|e: toml::de::Error| format!("[{name}] {}", e.message()))
}

/// The first `(key, value)` whose value is 0, for "must be > 0" checks in `validate()`.
pub fn first_zero<'a>(values: &[(&'a str, u64)]) -> Option<&'a str> {
    values.iter().find(|(_, v)| *v == 0).map(|(key, _)| *key)
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    use super::*;

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

    fn doc(text: &str) -> toml::Table {
        text.parse().unwrap()
    }

    #[test]
    fn a_table_overrides_defaults_and_a_missing_table_keeps_them() {
        let d = doc("[example]\nbatch_size = 64\n[other]\nanything = 1\n");
        let e: Example = table(&d, "example").unwrap();
        assert_eq!(e, Example { batch_size: 64, name: "x".into() });
        let missing: Example = table(&d, "missing").unwrap();
        assert_eq!(missing, Example::default());
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
        let over: Settings = table_over(&doc("[s]\nsquash = true\n"), "s", &base).unwrap();
        assert_eq!(over, Settings { scale: 3.0, squash: true, label: None });
        let none: Settings = table_over(&doc(""), "s", &base).unwrap();
        assert_eq!(none, base);
        let err = table_over::<Settings>(&doc("[s]\nsqash = true\n"), "s", &base).unwrap_err();
        assert!(err.starts_with("[s]") && err.contains("sqash"), "{err}");
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_errors_that_name_the_table() {
        let err = table::<Example>(&doc("[example]\nbatch_sise = 64\n"), "example").unwrap_err();
        assert!(err.starts_with("[example]") && err.contains("batch_sise"), "{err}");
        assert!(table::<Example>(&doc("[example]\nbatch_size = \"a\"\n"), "example").is_err());
        assert_eq!(first_zero(&[("a", 1), ("b", 0)]), Some("b"));
    }
}
