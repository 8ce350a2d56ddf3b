//! Bad input: a short reason for every way a message can be refused, counts by reason, and warnings
//! that stay readable in a flood (one line per reason per interval, with the count suppressed).

use proto::DecodeError;

/// Which input a rejected message arrived on; the prefix of its reason (`experience/checksum`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `experience/*`.
    Experience,
    /// `replay/priorities`.
    Priorities,
    /// `replay/sample` queries.
    Sample,
}

impl Input {
    fn as_str(self) -> &'static str {
        match self {
            Input::Experience => "experience",
            Input::Priorities => "priorities",
            Input::Sample => "sample",
        }
    }
}

/// The short reason for a decode failure (proto's [`DecodeError::reason`]).
pub fn decode_reason(error: &DecodeError) -> &'static str {
    error.reason()
}

/// One refused message: the input, a short reason, and the details for the log.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// The input it arrived on.
    pub input: Input,
    /// Short reason (`checksum`, `dims`, ...).
    pub reason: &'static str,
    /// Human-readable details.
    pub detail: String,
}

impl Rejection {
    /// A rejection for a decode error.
    pub fn decode(input: Input, error: &DecodeError) -> Self {
        Self { input, reason: decode_reason(error), detail: error.to_string() }
    }

    /// The counter key, `<input>/<reason>`.
    pub fn key(&self) -> String {
        format!("{}/{}", self.input.as_str(), self.reason)
    }
}

pub use node::Rejects;

#[cfg(test)]
mod tests {
    use super::*;
    use proto::{MessageKind, ValidationError};

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
            assert_eq!(decode_reason(&error), reason, "{error}");
        }
    }
}
