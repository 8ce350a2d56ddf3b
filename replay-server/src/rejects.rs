//! Bad input: a short reason for every way a message can be refused, counts by reason, and warnings
//! that stay readable in a flood (one line per reason per interval, with the count suppressed).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use proto::{DecodeError, ValidationError};

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

/// The short reason for a decode failure.
pub fn decode_reason(error: &DecodeError) -> &'static str {
    match error {
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
            ValidationError::Zero { .. } | ValidationError::BadText { .. } => "invalid",
        },
    }
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

/// Minimum time between two warnings for the same reason.
const WARN_EVERY: Duration = Duration::from_secs(5);

#[derive(Debug, Clone)]
struct WarnState {
    last: Instant,
    suppressed: u64,
}

/// Rejection counts by `<input>/<reason>` and the warning rate limit.
#[derive(Debug, Clone, Default)]
pub struct Rejects {
    counts: BTreeMap<String, u64>,
    warned: BTreeMap<String, WarnState>,
}

impl Rejects {
    /// Starts from restored counts.
    pub fn from_counts(counts: BTreeMap<String, u64>) -> Self {
        Self { counts, warned: BTreeMap::new() }
    }

    /// Counts `rejection` and logs it, unless this reason was logged less than 5 s before `now`.
    pub fn record(&mut self, rejection: &Rejection, now: Instant) {
        let key = rejection.key();
        *self.counts.entry(key.clone()).or_default() += 1;
        match self.warned.get_mut(&key) {
            Some(state) if now.duration_since(state.last) < WARN_EVERY => state.suppressed += 1,
            Some(state) => {
                tracing::warn!(reason = %key, detail = %rejection.detail, suppressed = state.suppressed, "rejected input");
                *state = WarnState { last: now, suppressed: 0 };
            }
            None => {
                tracing::warn!(reason = %key, detail = %rejection.detail, "rejected input");
                self.warned.insert(key, WarnState { last: now, suppressed: 0 });
            }
        }
    }

    /// Cumulative counts by reason.
    pub fn counts(&self) -> &BTreeMap<String, u64> {
        &self.counts
    }

    /// Total rejections of all reasons.
    pub fn total(&self) -> u64 {
        self.counts.values().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proto::MessageKind;

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

    #[test]
    fn counts_every_rejection_but_warns_once_per_interval() {
        let mut rejects = Rejects::default();
        let now = Instant::now();
        let r =
            Rejection::decode(Input::Experience, &DecodeError::ChecksumMismatch { expected: 1, found: 2 });
        for i in 0..1000 {
            rejects.record(&r, now + Duration::from_millis(i));
        }
        assert_eq!(rejects.counts().get("experience/checksum"), Some(&1000));
        assert_eq!(rejects.warned["experience/checksum"].suppressed, 999);
        rejects.record(&r, now + Duration::from_secs(6));
        assert_eq!(rejects.warned["experience/checksum"].suppressed, 0);
        assert_eq!(rejects.total(), 1001);
    }
}
