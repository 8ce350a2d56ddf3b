//! Typed errors: why a buffer was rejected ([`DecodeError`]), why a message's contents break the
//! contract ([`ValidationError`]), and why a run id or key expression is not one of ours ([`TopicError`]).

use crate::codec::MessageKind;

/// Result alias for decoding, the fallible operation every subscriber performs.
pub type Result<T, E = DecodeError> = std::result::Result<T, E>;

/// Why [`crate::decode`] rejected a buffer, checked in frame order: header, size, checksum, payload, contents.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The buffer ends before the header or before the payload length the header declares.
    #[error("buffer too short: need {needed} bytes, have {found}")]
    TooShort {
        /// Bytes the header (or header plus declared payload) needs.
        needed: usize,
        /// Bytes actually present.
        found: usize,
    },
    /// The first two bytes are not [`crate::codec::MAGIC`]: not one of our frames at all.
    #[error("bad magic {found:02x?}")]
    BadMagic {
        /// The two bytes found.
        found: [u8; 2],
    },
    /// The frame was written by a different format version of this crate.
    #[error("unsupported format version {found} (expected {expected})")]
    UnsupportedVersion {
        /// Version in the frame.
        found: u16,
        /// Version this build speaks.
        expected: u16,
    },
    /// The kind byte names no message type.
    #[error("unknown message kind {0}")]
    UnknownKind(u8),
    /// The frame holds a different message type than the one asked for.
    #[error("wrong message kind {found} (expected {expected})")]
    WrongKind {
        /// Kind in the frame.
        found: MessageKind,
        /// Kind the caller asked for.
        expected: MessageKind,
    },
    /// The declared payload length exceeds [`crate::codec::MAX_PAYLOAD_BYTES`].
    #[error("declared payload of {declared} bytes exceeds the limit of {max}")]
    PayloadTooLarge {
        /// Declared payload length.
        declared: u64,
        /// The limit.
        max: u64,
    },
    /// Bytes follow the declared payload, or the payload holds bytes the message did not consume.
    #[error("{extra} trailing bytes")]
    TrailingBytes {
        /// Number of unexpected bytes.
        extra: usize,
    },
    /// The payload's CRC32 differs from the header's: the bytes were corrupted in flight or in memory.
    #[error("checksum mismatch: header says {expected:#010x}, payload hashes to {found:#010x}")]
    ChecksumMismatch {
        /// CRC32 stored in the header.
        expected: u32,
        /// CRC32 of the payload received.
        found: u32,
    },
    /// bincode could not parse the payload (with a correct checksum: a sender bug, not line noise).
    #[error("malformed payload: {0}")]
    Malformed(String),
    /// The message parsed but breaks the contract (sizes, dimensions, non-finite floats, ...).
    #[error("invalid message: {0}")]
    Invalid(#[from] ValidationError),
}

impl DecodeError {
    /// A short, stable name for the failure, for counters on monitoring topics (`checksum`, `dims`).
    pub fn reason(&self) -> &'static str {
        match self {
            DecodeError::TooShort { .. } => "truncated",
            DecodeError::BadMagic { .. } => "bad_magic",
            DecodeError::UnsupportedVersion { .. } => "bad_version",
            DecodeError::UnknownKind(_) | DecodeError::WrongKind { .. } => "wrong_kind",
            DecodeError::PayloadTooLarge { .. } => "too_large",
            DecodeError::TrailingBytes { .. } => "trailing_bytes",
            DecodeError::ChecksumMismatch { .. } => "checksum",
            DecodeError::Malformed(_) => "malformed",
            DecodeError::Invalid(invalid) => match invalid {
                ValidationError::NonFinite { .. } => "non_finite",
                ValidationError::Negative { .. } => "negative",
                ValidationError::BadDimension { .. } => "dims",
                ValidationError::LengthMismatch { .. } => "length",
                ValidationError::Empty { .. } => "empty",
                ValidationError::TooLarge { .. } => "too_large",
                ValidationError::Zero { .. }
                | ValidationError::BadText { .. }
                | ValidationError::NotAFraction { .. } => "invalid",
            },
        }
    }
}

/// Why a message's contents break the wire contract; returned by [`crate::Message::validate`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidationError {
    /// A column's length does not match the transition count times its row width.
    #[error("{field}: length {found}, expected {expected}")]
    LengthMismatch {
        /// The offending field.
        field: &'static str,
        /// Length implied by the other fields.
        expected: usize,
        /// Length present.
        found: usize,
    },
    /// A float is NaN or infinite.
    #[error("{field}[{index}] is not finite")]
    NonFinite {
        /// The offending field.
        field: &'static str,
        /// Index of the first non-finite element.
        index: usize,
    },
    /// A float that must be non-negative (an absolute TD error, an importance weight) is negative.
    #[error("{field}[{index}] is negative")]
    Negative {
        /// The offending field.
        field: &'static str,
        /// Index of the first negative element.
        index: usize,
    },
    /// A fraction (a success rate) is not within [0, 1].
    #[error("{field} = {value} is not a fraction in [0, 1]")]
    NotAFraction {
        /// The offending field.
        field: &'static str,
        /// Value present.
        value: f64,
    },
    /// A dimension is zero or larger than [`crate::MAX_DIM`].
    #[error("{field} = {value} is outside 1..={max}")]
    BadDimension {
        /// The offending field.
        field: &'static str,
        /// Value present.
        value: u32,
        /// Largest accepted value.
        max: u32,
    },
    /// A field that must hold at least one element is empty.
    #[error("{field} is empty")]
    Empty {
        /// The offending field.
        field: &'static str,
    },
    /// A field holds more elements than the contract allows.
    #[error("{field}: {len} elements exceed the limit of {max}")]
    TooLarge {
        /// The offending field.
        field: &'static str,
        /// Elements present.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// A scalar that must be positive is zero.
    #[error("{field} must be positive")]
    Zero {
        /// The offending field.
        field: &'static str,
    },
    /// A name or text field breaks its format (characters, length, scheme prefix).
    #[error("{field} {value:?}: {reason}")]
    BadText {
        /// The offending field.
        field: &'static str,
        /// The text, cut to its first 64 characters.
        value: String,
        /// What rule it breaks.
        reason: &'static str,
    },
}

/// Why a run id, id segment or key expression is not one of ours.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TopicError {
    /// The run id is empty.
    #[error("run id is empty")]
    EmptyRunId,
    /// The run id is longer than [`crate::topics::MAX_RUN_ID_LEN`] bytes.
    #[error("run id is {len} bytes, longer than {max}")]
    RunIdTooLong {
        /// Its length in bytes.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// The run id holds a character that is special in key expressions, whitespace or a control character.
    #[error("run id {run_id:?} contains forbidden character {ch:?}")]
    ForbiddenChar {
        /// The run id given.
        run_id: String,
        /// The first forbidden character.
        ch: char,
    },
    /// A role segment names no role.
    #[error("unknown role {0:?}")]
    UnknownRole(String),
    /// A key expression is not under this run's prefix or matches none of our topics.
    #[error("key {0:?} is not a topic of this run")]
    UnknownKey(String),
    /// An id segment is not a canonical decimal `u32` (no sign, no leading zeros).
    #[error("bad id segment {0:?}")]
    BadId(String),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MessageKind;

    #[test]
    fn every_decode_error_has_a_short_reason() {
        let cases = [
            (DecodeError::TooShort { needed: 13, found: 2 }, "truncated"),
            (DecodeError::BadMagic { found: [0, 0] }, "bad_magic"),
            (DecodeError::UnsupportedVersion { found: 9, expected: 1 }, "bad_version"),
            (DecodeError::UnknownKind(77), "wrong_kind"),
            (
                DecodeError::WrongKind {
                    found: MessageKind::GlobalStep,
                    expected: MessageKind::ExperienceBatch,
                },
                "wrong_kind",
            ),
            (DecodeError::ChecksumMismatch { expected: 1, found: 2 }, "checksum"),
            (DecodeError::Malformed("x".into()), "malformed"),
            (DecodeError::Invalid(ValidationError::NonFinite { field: "rewards", index: 0 }), "non_finite"),
            (
                DecodeError::Invalid(ValidationError::BadDimension { field: "obs_dim", value: 0, max: 1 }),
                "dims",
            ),
        ];
        for (error, reason) in cases {
            assert_eq!(error.reason(), reason, "{error}");
        }
    }
}
