//! Sampling: the learner's query to the replay server, the reply, and the priority updates that
//! follow a gradient step.
//!
//! Sampled items are named by `(slot, generation)`: the slot is a ring-buffer index and the generation
//! counts how often that slot was overwritten, so a priority update that arrives after its item was
//! evicted is recognisable and dropped instead of re-prioritising the newer item in that slot.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;
use crate::experience::Transitions;

/// How long the replay server holds a sample request waiting for data before refusing it, unless
/// configured otherwise (`[replay_server] request_deadline_ms`). A sampler's own timeout must be
/// longer, or a held request looks like silence. Here because both sides of the exchange read it.
pub const DEFAULT_REQUEST_DEADLINE_MS: u64 = 1000;

/// The replay server's transition widths when its run file names none: Ant-v5's.
pub const DEFAULT_TRANSITION_DIMS: (u32, u32) = (105, 8);

/// Query payload on `replay/sample`: the learner asks for one batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleRequest {
    /// Chosen by the learner, echoed in the reply, so late replies to earlier requests are recognisable.
    pub request_id: u64,
    /// The learner's step when asking; the replay server's samples-per-insert limiter reads it.
    pub learner_step: u64,
    /// Transitions wanted, 1..=[`crate::MAX_BATCH_LEN`].
    pub batch_size: u32,
}

impl Sealed for SampleRequest {}

impl Message for SampleRequest {
    const KIND: MessageKind = MessageKind::SampleRequest;

    fn validate(&self) -> Result<(), ValidationError> {
        check::batch_len("batch_size", self.batch_size as usize)
    }
}

/// A prioritized sample: transitions plus what the learner needs to weight them and update priorities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampledBatch {
    /// The request this answers.
    pub request_id: u64,
    /// The request's `learner_step`, echoed.
    pub learner_step: u64,
    /// `n` ring-buffer slots the transitions came from.
    pub slots: Vec<u64>,
    /// `n` slot generations; see the module docs.
    pub generations: Vec<u64>,
    /// `n` importance-sampling weights `(N·P(i))^-β / max_j w_j`, finite and non-negative.
    #[serde(with = "crate::blob::f32s")]
    pub is_weights: Vec<f32>,
    /// The transitions.
    pub transitions: Transitions,
}

impl SampledBatch {
    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.transitions.len()
    }

    /// No transitions.
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty()
    }

    fn validate(&self) -> Result<(), ValidationError> {
        self.transitions.validate()?;
        let n = self.len();
        check::len("slots", n, self.slots.len())?;
        check::len("generations", n, self.generations.len())?;
        check::len("is_weights", n, self.is_weights.len())?;
        check::finite_non_negative("is_weights", &self.is_weights)
    }
}

/// Why the replay server did not sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RefusalReason {
    /// Fewer transitions stored than the configured minimum for sampling.
    BelowMinSize {
        /// Transitions stored now.
        have: u64,
        /// The configured minimum.
        min: u64,
    },
    /// Sampling now would push the samples-per-insert ratio over its limit; wait for executors.
    RateLimited {
        /// The ratio if this request were served.
        samples_per_insert: f64,
        /// The configured limit.
        max_samples_per_insert: f64,
    },
    /// The request asks for more transitions than the server serves at once.
    BatchTooLarge {
        /// Batch size requested.
        requested: u32,
        /// Largest batch served.
        max: u32,
    },
    /// The server is shutting down.
    ShuttingDown,
    /// Anything else, explained in at most [`crate::MAX_TEXT_LEN`] bytes.
    Other {
        /// The explanation.
        detail: String,
    },
}

impl fmt::Display for RefusalReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RefusalReason::BelowMinSize { have, min } => write!(f, "below min size {min} (have {have})"),
            RefusalReason::RateLimited { samples_per_insert, max_samples_per_insert } => write!(
                f,
                "rate limited: {samples_per_insert:.2} samples per insert would exceed {max_samples_per_insert:.2}"
            ),
            RefusalReason::BatchTooLarge { requested, max } => {
                write!(f, "batch of {requested} exceeds the maximum of {max}")
            }
            RefusalReason::ShuttingDown => f.write_str("shutting down"),
            RefusalReason::Other { detail } => f.write_str(detail),
        }
    }
}

/// A refusal with a hint for when to ask again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleRefusal {
    /// The request this answers.
    pub request_id: u64,
    /// Why.
    pub reason: RefusalReason,
    /// Suggested wait before the next request; 0 means "any time".
    pub retry_after_ms: u32,
}

impl SampleRefusal {
    fn validate(&self) -> Result<(), ValidationError> {
        match &self.reason {
            RefusalReason::RateLimited { samples_per_insert, max_samples_per_insert } => {
                check::finite_f64("samples_per_insert", *samples_per_insert)?;
                check::finite_f64("max_samples_per_insert", *max_samples_per_insert)
            }
            RefusalReason::Other { detail } => check::text("detail", detail),
            RefusalReason::BelowMinSize { .. } | RefusalReason::BatchTooLarge { .. } => Ok(()),
            RefusalReason::ShuttingDown => Ok(()),
        }
    }
}

/// Reply payload on `replay/sample`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SampleReply {
    /// The batch asked for.
    Batch(SampledBatch),
    /// No batch, and why.
    Refused(SampleRefusal),
}

impl SampleReply {
    /// The `request_id` this reply answers.
    pub fn request_id(&self) -> u64 {
        match self {
            SampleReply::Batch(batch) => batch.request_id,
            SampleReply::Refused(refusal) => refusal.request_id,
        }
    }
}

impl Sealed for SampleReply {
    fn payload_size_hint(&self) -> usize {
        match self {
            // Slots and generations are varints of at most 10 bytes each.
            SampleReply::Batch(b) => {
                b.transitions.payload_size_hint() + 4 * b.is_weights.len() + 20 * b.len() + 64
            }
            SampleReply::Refused(_) => 128,
        }
    }
}

impl Message for SampleReply {
    const KIND: MessageKind = MessageKind::SampleReply;

    fn validate(&self) -> Result<(), ValidationError> {
        match self {
            SampleReply::Batch(batch) => batch.validate(),
            SampleReply::Refused(refusal) => refusal.validate(),
        }
    }
}

/// New priorities after a gradient step; topic `replay/priorities`, learner → replay server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorityUpdate {
    /// The learner step whose TD errors these are.
    pub learner_step: u64,
    /// `n` slots, as sampled.
    pub slots: Vec<u64>,
    /// `n` generations, as sampled; a mismatch on the server means the item was evicted.
    pub generations: Vec<u64>,
    /// `n` absolute TD errors `|δ|`; the replay server turns them into priorities.
    #[serde(with = "crate::blob::f32s")]
    pub td_errors: Vec<f32>,
}

impl Sealed for PriorityUpdate {
    fn payload_size_hint(&self) -> usize {
        24 * self.slots.len() + 64
    }
}

impl Message for PriorityUpdate {
    const KIND: MessageKind = MessageKind::PriorityUpdate;

    fn validate(&self) -> Result<(), ValidationError> {
        let n = self.slots.len();
        check::batch_len("slots", n)?;
        check::len("generations", n, self.generations.len())?;
        check::len("td_errors", n, self.td_errors.len())?;
        check::finite_non_negative("td_errors", &self.td_errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusal_reasons_read_as_sentences() {
        let below = RefusalReason::BelowMinSize { have: 512, min: 10_000 };
        assert_eq!(below.to_string(), "below min size 10000 (have 512)");
        let limited = RefusalReason::RateLimited { samples_per_insert: 256.5, max_samples_per_insert: 256.0 };
        assert_eq!(limited.to_string(), "rate limited: 256.50 samples per insert would exceed 256.00");
    }

    #[test]
    fn refusal_validation() {
        let refusal =
            |reason| SampleReply::Refused(SampleRefusal { request_id: 1, reason, retry_after_ms: 5 });
        let nan =
            refusal(RefusalReason::RateLimited { samples_per_insert: f64::NAN, max_samples_per_insert: 1.0 });
        assert_eq!(nan.validate(), Err(ValidationError::NonFinite { field: "samples_per_insert", index: 0 }));
        let long = refusal(RefusalReason::Other { detail: "x".repeat(513) });
        assert!(matches!(long.validate(), Err(ValidationError::BadText { field: "detail", .. })));
        assert_eq!(refusal(RefusalReason::ShuttingDown).validate(), Ok(()));
        assert_eq!(refusal(RefusalReason::ShuttingDown).request_id(), 1);
    }

    #[test]
    fn priority_update_lengths_must_agree() {
        let update = PriorityUpdate {
            learner_step: 1,
            slots: vec![1, 2],
            generations: vec![0],
            td_errors: vec![0.1, 0.2],
        };
        assert_eq!(
            update.validate(),
            Err(ValidationError::LengthMismatch { field: "generations", expected: 2, found: 1 })
        );
        let empty = PriorityUpdate { learner_step: 1, slots: vec![], generations: vec![], td_errors: vec![] };
        assert_eq!(empty.validate(), Err(ValidationError::Empty { field: "slots" }));
    }
}
