//! Typed errors: configuration, buffer operations, snapshots.

use crate::config::Dims;

/// A `Result` whose error defaults to [`ReplayError`].
pub type Result<T, E = ReplayError> = std::result::Result<T, E>;

/// An invalid [`ReplayConfig`](crate::ReplayConfig) (or task dimensions), from `validate()`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// The observation has no components.
    #[error("obs_dim must be at least 1")]
    ObsDim,
    /// The action has no components.
    #[error("act_dim must be at least 1")]
    ActDim,
    /// The ring has no slots.
    #[error("capacity_transitions must be at least 1")]
    CapacityZero,
    /// The ring is larger than `u32` row positions can address.
    #[error("capacity_transitions must be at most 4294967295, got {got}")]
    CapacityTooLarge {
        /// The configured capacity.
        got: usize,
    },
    /// Too few observation rows for one transition, or more than `u32` positions can address.
    #[error("observation_rows must be in [2, 4294967295] (a transition uses two rows), got {got}")]
    ObservationRows {
        /// The configured (or defaulted) number of rows.
        got: usize,
    },
    /// α outside [0, 1] or NaN.
    #[error("alpha must be in [0, 1], got {got}")]
    Alpha {
        /// The configured α.
        got: f64,
    },
    /// ε not a finite positive number.
    #[error("epsilon must be finite and positive, got {got}")]
    Epsilon {
        /// The configured ε.
        got: f64,
    },
    /// β start outside [0, 1] or NaN.
    #[error("beta_start must be in [0, 1], got {got}")]
    BetaStart {
        /// The configured start.
        got: f64,
    },
    /// β end below the start, above 1 or NaN (β above 1 over-corrects: the paper's bug).
    #[error("beta_end must be in [beta_start, 1], got {got} with beta_start {beta_start}")]
    BetaEnd {
        /// The configured end.
        got: f64,
        /// The configured start.
        beta_start: f64,
    },
    /// The storage would need more bytes than `memory_budget_bytes`.
    #[error("replay storage needs {needed} bytes, more than memory_budget_bytes {budget}")]
    OverBudget {
        /// Bytes the configuration would allocate.
        needed: u64,
        /// The configured budget.
        budget: u64,
    },
}

/// A refused buffer operation. Nothing is modified when one is returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplayError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An input slice has the wrong length for the batch size and dimensions.
    #[error("{field} has {found} values, expected {expected}")]
    Length {
        /// Name of the input slice.
        field: &'static str,
        /// Length implied by the batch size (and obs/act dims).
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// An input value is NaN or infinite.
    #[error("{field}[{index}] is not finite")]
    NonFinite {
        /// Name of the input slice.
        field: &'static str,
        /// Index of the first bad value in that slice.
        index: usize,
    },
    /// A TD-error magnitude is negative, NaN or infinite.
    #[error("abs_td_errors[{index}] = {value} is not a finite non-negative number")]
    InvalidAbsTdError {
        /// Index of the first bad value.
        index: usize,
        /// The value.
        value: f32,
    },
    /// A priority update names a slot outside the ring.
    #[error("slots[{index}] = {slot} is outside the ring of capacity {capacity}")]
    SlotOutOfRange {
        /// Index in the update.
        index: usize,
        /// The slot named.
        slot: u64,
        /// Ring capacity.
        capacity: usize,
    },
    /// Sampling from a buffer that holds nothing.
    #[error("cannot sample from an empty buffer")]
    Empty,
    /// Sampling a batch of size zero.
    #[error("batch_size must be at least 1")]
    ZeroBatchSize,
}

/// A snapshot that could not be written or restored.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Reading or writing failed (a truncated snapshot shows up as `UnexpectedEof`).
    #[error("snapshot i/o: {0}")]
    Io(#[from] std::io::Error),
    /// The data does not start with the snapshot magic: not a replay snapshot.
    #[error("not a replay snapshot (bad magic)")]
    BadMagic,
    /// The snapshot was written by a format version this build does not read.
    #[error("snapshot format version {found} is not supported (this build reads {supported})")]
    UnsupportedVersion {
        /// Version in the snapshot.
        found: u32,
        /// Version this build reads and writes.
        supported: u32,
    },
    /// The snapshot holds transitions of other dimensions (another task).
    #[error("snapshot dims ({found}) differ from the task's ({expected})")]
    DimsMismatch {
        /// The task's dimensions.
        expected: Dims,
        /// The snapshot's dimensions.
        found: Dims,
    },
    /// A field that shapes the stored state (capacity, rows, α, ε) differs from the configuration.
    #[error("snapshot {field} is {found}, the configuration says {expected}")]
    ConfigMismatch {
        /// Config field name.
        field: &'static str,
        /// Configured value.
        expected: String,
        /// Value in the snapshot.
        found: String,
    },
    /// The checksum at the end does not match the data: the snapshot is corrupt.
    #[error("snapshot checksum mismatch (corrupt data)")]
    ChecksumMismatch,
    /// The checksum matched but the contents break an invariant of the buffer.
    #[error("snapshot is inconsistent: {0}")]
    Corrupt(&'static str),
    /// The configuration given for the restore is itself invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
}
