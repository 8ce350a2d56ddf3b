//! Durable experience: what the replay server has made durable, per executor stream.
//!
//! An executor keeps every batch it publishes in its spool until the replay server says the batch
//! is durable: decided (stored, or refused for a counted reason) and covered by a snapshot written
//! after that. The replay server restores that snapshot after a restart, so what the spool still
//! holds is exactly what a re-send must cover; batches the snapshot already holds are recognised by
//! their (`executor_id`, `stream`, `seq`) and not stored twice.

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// Most streams one [`DurableMarks`] may name: executors times the restarts a replay server
/// remembers (it forgets the oldest streams past this).
pub const MAX_STREAM_MARKS: usize = 4096;

/// One executor stream's durable prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamMark {
    /// The executor.
    pub executor_id: u32,
    /// Its stream (nonzero).
    pub stream: u64,
    /// Every batch of the stream with a smaller `seq` is durable.
    pub durable_below: u64,
}

/// `replay/durable` (replay server → executors): after each snapshot becomes durable, and again
/// every stats interval so that a restarted executor learns about the streams of its earlier runs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DurableMarks {
    /// The snapshot these marks are covered by.
    pub snapshot_sequence: u64,
    /// Every stream the snapshot knows, at most [`MAX_STREAM_MARKS`].
    pub marks: Vec<StreamMark>,
}

impl DurableMarks {
    /// Where every batch of (`executor_id`, `stream`) below the returned `seq` is durable.
    pub fn durable_below(&self, executor_id: u32, stream: u64) -> Option<u64> {
        self.marks
            .iter()
            .find(|m| m.executor_id == executor_id && m.stream == stream)
            .map(|m| m.durable_below)
    }
}

impl Sealed for DurableMarks {
    fn payload_size_hint(&self) -> usize {
        24 * self.marks.len() + 16
    }
}

impl Message for DurableMarks {
    const KIND: MessageKind = MessageKind::DurableMarks;

    fn validate(&self) -> Result<(), ValidationError> {
        check::at_most("marks", self.marks.len(), MAX_STREAM_MARKS)?;
        if self.marks.iter().any(|m| m.stream == 0) {
            return Err(ValidationError::Zero { field: "marks.stream" });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_round_trip_and_name_each_stream() {
        let marks = DurableMarks {
            snapshot_sequence: 7,
            marks: vec![
                StreamMark { executor_id: 0, stream: 11, durable_below: 40 },
                StreamMark { executor_id: 1, stream: 12, durable_below: 3 },
            ],
        };
        let back: DurableMarks = crate::decode(&crate::encode(&marks)).unwrap();
        assert_eq!(back, marks);
        assert_eq!(marks.durable_below(1, 12), Some(3));
        assert_eq!(marks.durable_below(1, 11), None, "another executor's stream");
        let zero =
            DurableMarks { marks: vec![StreamMark { executor_id: 0, stream: 0, durable_below: 1 }], ..marks };
        assert!(zero.validate().is_err(), "stream 0 is never spooled");
    }
}
