//! The crate's error type.

/// Everything that can go wrong in the agent.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor operation failed inside candle.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
    /// An [`AgentConfig`](crate::AgentConfig) field is out of range; the message names it.
    #[error("invalid agent config: {0}")]
    InvalidConfig(String),
    /// A [`Batch`](crate::Batch) or observation does not match the configured dimensions.
    #[error("bad input: {0}")]
    BadInput(String),
    /// A parameter snapshot or checkpoint is malformed, or does not fit the networks.
    #[error("bad snapshot: {0}")]
    BadSnapshot(String),
    /// The levels of a [`PolicyStack`](crate::PolicyStack) do not chain.
    #[error("bad policy stack: {0}")]
    BadStack(String),
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
