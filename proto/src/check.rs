//! Contract limits and the small checks every message's `validate` is built from.
//!
//! The limits are far above what an Ant run needs; they exist so that a buggy or hostile sender
//! cannot make a receiver allocate or loop without bound after a frame has passed its checksum.

use crate::error::ValidationError;

/// Largest observation or action dimension accepted.
pub const MAX_DIM: u32 = 4096;
/// Most transitions (or priority entries) one message may carry.
pub const MAX_BATCH_LEN: usize = 1 << 16;
/// Longest metric, reason or blocked-on name, in bytes.
pub const MAX_NAME_LEN: usize = 128;
/// Longest free-form text (blocked-on explanation, refusal detail), in bytes.
pub const MAX_TEXT_LEN: usize = 512;
/// Most entries in each list of a stats report.
pub const MAX_STATS_ENTRIES: usize = 1024;

/// `value` is a usable dimension: 1..=MAX_DIM.
pub(crate) fn dim(field: &'static str, value: u32) -> Result<(), ValidationError> {
    if value == 0 || value > MAX_DIM {
        return Err(ValidationError::BadDimension { field, value, max: MAX_DIM });
    }
    Ok(())
}

/// `found == expected`.
pub(crate) fn len(field: &'static str, expected: usize, found: usize) -> Result<(), ValidationError> {
    if found != expected {
        return Err(ValidationError::LengthMismatch { field, expected, found });
    }
    Ok(())
}

/// A batch length: 1..=MAX_BATCH_LEN.
pub(crate) fn batch_len(field: &'static str, n: usize) -> Result<(), ValidationError> {
    if n == 0 {
        return Err(ValidationError::Empty { field });
    }
    if n > MAX_BATCH_LEN {
        return Err(ValidationError::TooLarge { field, len: n, max: MAX_BATCH_LEN });
    }
    Ok(())
}

/// Every element is finite.
pub(crate) fn finite(field: &'static str, values: &[f32]) -> Result<(), ValidationError> {
    // The all-finite fast path is a branch-free reduction the compiler vectorises; the index is
    // only searched for once we know there is something to report.
    if values.iter().fold(true, |ok, v| ok & v.is_finite()) {
        return Ok(());
    }
    let index = values.iter().position(|v| !v.is_finite()).unwrap_or_default();
    Err(ValidationError::NonFinite { field, index })
}

/// Every element is finite and non-negative.
pub(crate) fn finite_non_negative(field: &'static str, values: &[f32]) -> Result<(), ValidationError> {
    finite(field, values)?;
    // `-0.0 >= 0.0` holds, so a negative zero passes, as it should.
    match values.iter().position(|v| *v < 0.0) {
        Some(index) => Err(ValidationError::Negative { field, index }),
        None => Ok(()),
    }
}

/// A single `f64` is finite.
pub(crate) fn finite_f64(field: &'static str, value: f64) -> Result<(), ValidationError> {
    if !value.is_finite() {
        return Err(ValidationError::NonFinite { field, index: 0 });
    }
    Ok(())
}

/// A fraction, when present, lies in [0, 1] (NaN does not).
pub(crate) fn fraction(field: &'static str, value: Option<f64>) -> Result<(), ValidationError> {
    match value {
        Some(value) if !(0.0..=1.0).contains(&value) => Err(ValidationError::NotAFraction { field, value }),
        _ => Ok(()),
    }
}

/// A scalar is non-zero.
pub(crate) fn positive(field: &'static str, value: u64) -> Result<(), ValidationError> {
    if value == 0 {
        return Err(ValidationError::Zero { field });
    }
    Ok(())
}

/// A list holds at most `max` entries.
pub(crate) fn at_most(field: &'static str, n: usize, max: usize) -> Result<(), ValidationError> {
    if n > max {
        return Err(ValidationError::TooLarge { field, len: n, max });
    }
    Ok(())
}

/// A name: 1..=MAX_NAME_LEN bytes of `[A-Za-z0-9_./-]`, so it can be a path in a monitor or a
/// Prometheus label after replacing `/`.
pub(crate) fn name(field: &'static str, value: &str) -> Result<(), ValidationError> {
    let reason = if value.is_empty() {
        "empty"
    } else if value.len() > MAX_NAME_LEN {
        "longer than 128 bytes"
    } else if !value.bytes().all(|b| b.is_ascii_alphanumeric() || b"_./-".contains(&b)) {
        "only ASCII letters, digits and _ . / - are allowed"
    } else {
        return Ok(());
    };
    Err(bad_text(field, value, reason))
}

/// Free text: at most MAX_TEXT_LEN bytes, no control characters (it ends up in logs and terminals).
pub(crate) fn text(field: &'static str, value: &str) -> Result<(), ValidationError> {
    let reason = if value.len() > MAX_TEXT_LEN {
        "longer than 512 bytes"
    } else if value.chars().any(char::is_control) {
        "contains control characters"
    } else {
        return Ok(());
    };
    Err(bad_text(field, value, reason))
}

/// Builds a [`ValidationError::BadText`], keeping the echoed value short.
pub(crate) fn bad_text(field: &'static str, value: &str, reason: &'static str) -> ValidationError {
    ValidationError::BadText { field, value: value.chars().take(64).collect(), reason }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_reports_first_bad_index() {
        assert_eq!(finite("x", &[1.0, 2.0]), Ok(()));
        assert_eq!(
            finite("x", &[1.0, f32::INFINITY, f32::NAN]),
            Err(ValidationError::NonFinite { field: "x", index: 1 })
        );
        assert_eq!(
            finite_non_negative("x", &[0.0, -0.0, -1.0]),
            Err(ValidationError::Negative { field: "x", index: 2 })
        );
    }

    #[test]
    fn names_and_text() {
        assert!(name("n", "learner/q_loss").is_ok());
        assert!(name("n", "").is_err());
        assert!(name("n", "has space").is_err());
        assert!(name("n", &"a".repeat(129)).is_err());
        assert!(text("t", "waiting for learner step 12").is_ok());
        assert!(text("t", "line\nbreak").is_err());
        assert!(dim("d", 0).is_err() && dim("d", 4097).is_err() && dim("d", 105).is_ok());
    }
}
