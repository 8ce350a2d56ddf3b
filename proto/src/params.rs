//! Parameters: weight snapshots from the learner, through the param server, to executors.

use serde::{Deserialize, Serialize};

use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// The policy's weights at one global step.
///
/// Topics: `params/publish` (learner → param server) and `params/weights` (param server → executors,
/// plus a queryable with the same key that answers with the latest snapshot, so a late joiner does not
/// wait for the next broadcast; it does not reply before the first snapshot exists).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WeightsSnapshot {
    /// The global (learner) step at which these weights were produced; executors tag their
    /// experience with it, and policy lag is measured against it.
    pub version: u64,
    /// The learner's step when it published (equal to `version` unless publishing lags the update).
    pub learner_step: u64,
    /// A safetensors file, named by the agent's `VarBuilder` prefix tree; opaque to this crate.
    #[serde(with = "crate::blob::bytes")]
    pub safetensors: Vec<u8>,
}

impl Sealed for WeightsSnapshot {
    fn payload_size_hint(&self) -> usize {
        self.safetensors.len() + 64
    }
}

impl Message for WeightsSnapshot {
    const KIND: MessageKind = MessageKind::WeightsSnapshot;

    /// Only non-emptiness: the bytes are the agent crate's to parse, and the frame limit bounds their size.
    fn validate(&self) -> Result<(), ValidationError> {
        if self.safetensors.is_empty() {
            return Err(ValidationError::Empty { field: "safetensors" });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_weights_are_invalid() {
        let snapshot = WeightsSnapshot { version: 1, learner_step: 1, safetensors: vec![] };
        assert_eq!(snapshot.validate(), Err(ValidationError::Empty { field: "safetensors" }));
    }
}
