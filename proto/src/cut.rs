//! `replay/cut`: where a deterministic run resumes, as the replay server's newest cut says.

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// The replay server's deterministic state (`run::lockstep`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CutState {
    /// The checkpoint step of its newest cut (0: none; a fresh run).
    pub learner_step: u64,
    /// Whether it cuts at checkpoint steps at all (it does only with a snapshot to write).
    pub cuts: bool,
    /// Env steps each executor has delivered, by executor id.
    pub progress: Vec<u64>,
}

/// The reply of the `replay/cut` queryable (replay server → learner and executors at start).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReplayCut {
    /// Its state; `None` when it does not run deterministic mode.
    pub lockstep: Option<CutState>,
}

impl Sealed for ReplayCut {
    fn payload_size_hint(&self) -> usize {
        24 + 8 * self.lockstep.as_ref().map_or(0, |s| s.progress.len())
    }
}

impl Message for ReplayCut {
    const KIND: MessageKind = MessageKind::ReplayCut;

    fn validate(&self) -> Result<(), ValidationError> {
        let executors = self.lockstep.as_ref().map_or(0, |s| s.progress.len());
        check::at_most("lockstep.progress", executors, crate::MAX_BATCH_LEN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cuts_round_trip() {
        let cut = ReplayCut {
            lockstep: Some(CutState { learner_step: 500, cuts: true, progress: vec![1250, 1250] }),
        };
        assert_eq!(crate::decode::<ReplayCut>(&crate::encode(&cut)), Ok(cut));
        let normal = ReplayCut { lockstep: None };
        assert_eq!(crate::decode::<ReplayCut>(&crate::encode(&normal)), Ok(normal));
    }
}
