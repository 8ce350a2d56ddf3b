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
    /// For a level trained on top of frozen levels: the [`FrozenLevels::content_hash`] of the
    /// stack it was trained on. The param server and executors refuse weights whose stack is not
    /// theirs. `None` for a single-level run.
    pub stack: Option<ContentHash>,
}

/// SHA3-256 of a hierarchy's frozen acting weights (`agent::PolicyStack::content_hash`).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ContentHash(pub [u8; 32]);

impl std::fmt::Display for ContentHash {
    /// Lowercase hex, as `sha3sum` prints it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.iter().try_for_each(|b| write!(f, "{b:02x}"))
    }
}

impl ContentHash {
    /// What a weights frame's `stack` names, for messages: the hash, or "no frozen levels".
    pub fn describe(stack: Option<ContentHash>) -> String {
        stack.map_or_else(|| "no frozen levels".to_string(), |h| h.to_string())
    }
}

impl std::fmt::Debug for ContentHash {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ContentHash({self})")
    }
}

/// The frozen lower levels of a hierarchy, as the param server serves them once to every executor
/// (topic `params/frozen`, a queryable), so executors on other hosts need no files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrozenLevels {
    /// The hash of the acting weights; receivers recompute it from `levels` and compare.
    pub content_hash: ContentHash,
    /// Each level's networks as a safetensors file, bottom (env-facing) level first.
    pub levels: Vec<FrozenLevel>,
}

/// One frozen level's weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrozenLevel {
    /// A safetensors file holding the level's networks; opaque to this crate.
    #[serde(with = "crate::blob::bytes")]
    pub safetensors: Vec<u8>,
}

/// At most this many frozen levels in one [`FrozenLevels`].
pub const MAX_FROZEN_LEVELS: usize = 16;

impl Sealed for FrozenLevels {
    fn payload_size_hint(&self) -> usize {
        self.levels.iter().map(|l| l.safetensors.len() + 8).sum::<usize>() + 64
    }
}

impl Message for FrozenLevels {
    const KIND: MessageKind = MessageKind::FrozenLevels;

    /// One to [`MAX_FROZEN_LEVELS`] levels, none empty; the bytes are the agent crate's to parse.
    fn validate(&self) -> Result<(), ValidationError> {
        if self.levels.is_empty() {
            return Err(ValidationError::Empty { field: "levels" });
        }
        if self.levels.len() > MAX_FROZEN_LEVELS {
            return Err(ValidationError::TooLarge {
                field: "levels",
                len: self.levels.len(),
                max: MAX_FROZEN_LEVELS,
            });
        }
        if self.levels.iter().any(|l| l.safetensors.is_empty()) {
            return Err(ValidationError::Empty { field: "levels.safetensors" });
        }
        Ok(())
    }
}

impl WeightsSnapshot {
    /// Why these weights do not fit a run acting through the frozen levels hashed `expected` (the
    /// levels below would read their h as something else), or `None` when they do.
    pub fn stack_mismatch(&self, expected: Option<ContentHash>) -> Option<String> {
        (self.stack != expected).then(|| {
            format!(
                "version {}: trained on {}, this run acts on {}",
                self.version,
                ContentHash::describe(self.stack),
                ContentHash::describe(expected)
            )
        })
    }
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
        let snapshot = WeightsSnapshot { version: 1, learner_step: 1, safetensors: vec![], stack: None };
        assert_eq!(snapshot.validate(), Err(ValidationError::Empty { field: "safetensors" }));
    }

    #[test]
    fn frozen_levels_need_one_to_sixteen_non_empty_levels() {
        let level = FrozenLevel { safetensors: vec![1, 2] };
        let frozen = |levels: Vec<FrozenLevel>| FrozenLevels { content_hash: ContentHash([7; 32]), levels };
        assert_eq!(frozen(vec![level.clone()]).validate(), Ok(()));
        assert_eq!(frozen(vec![]).validate(), Err(ValidationError::Empty { field: "levels" }));
        assert!(frozen(vec![level; MAX_FROZEN_LEVELS + 1]).validate().is_err());
        let empty = frozen(vec![FrozenLevel { safetensors: vec![] }]);
        assert_eq!(empty.validate(), Err(ValidationError::Empty { field: "levels.safetensors" }));
        assert_eq!(ContentHash([0xab; 32]).to_string(), "ab".repeat(32));
    }
}
