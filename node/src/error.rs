use std::path::PathBuf;

use thiserror::Error;

/// Why a node could not start or talk on the bus.
#[derive(Debug, Error)]
pub enum NodeError {
    /// A config file could not be read.
    #[error("cannot read config {path}: {source}")]
    ConfigRead {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A config file is not valid TOML or its table does not match the crate's config struct.
    #[error("config {path}, table [{section}]: {message}")]
    ConfigParse {
        /// The file.
        path: PathBuf,
        /// The table.
        section: String,
        /// What is wrong.
        message: String,
    },
    /// A config value is out of range (the crate's `validate()` said why).
    #[error("config table [{section}] is invalid: {message}")]
    ConfigInvalid {
        /// The table.
        section: String,
        /// What is wrong.
        message: String,
    },
    /// The run id cannot be used in key expressions.
    #[error("bad run id: {0}")]
    RunId(#[from] proto::TopicError),
    /// zenoh refused a configuration value or could not open or use the session.
    #[error("zenoh: {0}")]
    Zenoh(String),
}

impl NodeError {
    /// Wraps one of zenoh's boxed errors, which `?` cannot convert.
    pub fn zenoh(e: impl std::fmt::Display) -> Self {
        NodeError::Zenoh(e.to_string())
    }
}
