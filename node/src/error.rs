use thiserror::Error;

/// Why a node could not start or talk on the bus.
#[derive(Debug, Error)]
pub enum NodeError {
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
