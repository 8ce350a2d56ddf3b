//! Which batches of each executor stream the server has decided (stored, or refused for a counted
//! reason), sans-IO: what recognises a re-sent batch, what a snapshot's durable marks say, and which
//! decided batches were refused (the experience audit's `refused` column, never `stored`).
//!
//! Executors send a stream's batches in order and re-send them in order, so a stream is a prefix
//! (`below`: every batch under it decided) plus the few decided out of order past it (a re-send
//! overtaken by a new batch). The table is saved in every snapshot with the buffer it describes.

use std::collections::{BTreeMap, BTreeSet};

use proto::{MAX_STREAM_MARKS, StreamMark};
use serde::{Deserialize, Serialize};

/// One stream's decided batches.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
struct Seen {
    /// Every `seq` below this is decided.
    below: u64,
    /// Decided past `below`.
    ahead: BTreeSet<u64>,
    /// When the stream last sent (the table's clock), to forget the stalest first.
    touched: u64,
}

/// Key of a stream: (executor id, stream id).
type Key = (u32, u64);

/// Decided batches of every stream, at most [`MAX_STREAM_MARKS`] streams (the stalest forgotten).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Streams {
    streams: BTreeMap<Key, Seen>,
    clock: u64,
    /// Per stream, the decided batches that were refused, as ranges `start → end` (end excluded):
    /// refusals are rare, and when a misconfigured executor has every batch refused they are one
    /// range. Forgotten with their stream.
    refused: BTreeMap<Key, BTreeMap<u64, u64>>,
}

/// The table as snapshot format 3 and earlier saved it (before refusals were told apart), read and
/// upgraded: its refused batches are not known, so they read as stored.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct StreamsV3 {
    streams: BTreeMap<Key, Seen>,
    clock: u64,
}

impl From<StreamsV3> for Streams {
    fn from(v3: StreamsV3) -> Self {
        Streams { streams: v3.streams, clock: v3.clock, refused: BTreeMap::new() }
    }
}

#[cfg(test)]
impl From<Streams> for StreamsV3 {
    fn from(s: Streams) -> Self {
        StreamsV3 { streams: s.streams, clock: s.clock }
    }
}

impl Streams {
    /// Whether batch `seq` of (`executor_id`, `stream`) was decided already.
    pub fn seen(&self, executor_id: u32, stream: u64, seq: u64) -> bool {
        self.streams.get(&(executor_id, stream)).is_some_and(|s| seq < s.below || s.ahead.contains(&seq))
    }

    /// Whether batch `seq` of (`executor_id`, `stream`) was decided by refusing it.
    pub fn refused(&self, executor_id: u32, stream: u64, seq: u64) -> bool {
        let Some(ranges) = self.refused.get(&(executor_id, stream)) else { return false };
        ranges.range(..=seq).next_back().is_some_and(|(_, &end)| seq < end)
    }

    /// Records batch `seq` of (`executor_id`, `stream`) as decided: stored, or refused if
    /// `refused` (for the audit; a batch decided already keeps its first decision).
    pub fn decide(&mut self, executor_id: u32, stream: u64, seq: u64, refused: bool) {
        if refused && !self.seen(executor_id, stream, seq) {
            let ranges = self.refused.entry((executor_id, stream)).or_default();
            // Batches come in order: the one after a refused range extends it.
            match ranges.range_mut(..=seq).next_back() {
                Some((_, end)) if *end == seq => *end += 1,
                _ => {
                    ranges.insert(seq, seq + 1);
                }
            }
            if let Some(&next_end) = ranges.get(&(seq + 1)) {
                ranges.remove(&(seq + 1));
                if let Some((_, end)) = ranges.range_mut(..=seq).next_back() {
                    *end = next_end;
                }
            }
        }
        self.record(executor_id, stream, seq);
    }

    /// Records batch `seq` of (`executor_id`, `stream`) as decided (stored).
    pub fn record(&mut self, executor_id: u32, stream: u64, seq: u64) {
        self.clock += 1;
        if !self.streams.contains_key(&(executor_id, stream)) && self.streams.len() >= MAX_STREAM_MARKS {
            let stalest = self.streams.iter().min_by_key(|(_, s)| s.touched).map(|(k, _)| *k);
            if let Some(key) = stalest {
                self.streams.remove(&key);
                self.refused.remove(&key);
            }
        }
        let seen = self.streams.entry((executor_id, stream)).or_default();
        seen.touched = self.clock;
        if seq < seen.below {
            return;
        }
        seen.ahead.insert(seq);
        while seen.ahead.remove(&seen.below) {
            seen.below += 1;
        }
    }

    /// Each stream's decided prefix.
    pub fn marks(&self) -> Vec<StreamMark> {
        self.streams
            .iter()
            .map(|(&(executor_id, stream), s)| StreamMark { executor_id, stream, durable_below: s.below })
            .collect()
    }

    /// Streams known.
    pub fn len(&self) -> usize {
        self.streams.len()
    }

    /// No stream known.
    pub fn is_empty(&self) -> bool {
        self.streams.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_prefix_grows_over_batches_decided_out_of_order() {
        let mut s = Streams::default();
        s.record(0, 9, 0);
        s.record(0, 9, 2);
        assert!(s.seen(0, 9, 0) && s.seen(0, 9, 2));
        assert!(!s.seen(0, 9, 1), "a gap is not decided");
        assert!(!s.seen(1, 9, 0) && !s.seen(0, 8, 0), "other executors and streams are their own");
        assert_eq!(s.marks(), [StreamMark { executor_id: 0, stream: 9, durable_below: 1 }]);
        s.record(0, 9, 1);
        assert_eq!(s.marks()[0].durable_below, 3, "the gap closed, and the prefix took what was ahead");
        s.record(0, 9, 1);
        assert_eq!(s.marks()[0].durable_below, 3, "a repeat changes nothing");
    }

    #[test]
    fn refused_batches_are_decided_and_told_apart_from_stored_ones() {
        let mut s = Streams::default();
        s.decide(0, 9, 0, false);
        for seq in [1, 2, 4, 3] {
            s.decide(0, 9, seq, true);
        }
        s.decide(0, 9, 5, false);
        s.decide(0, 9, 0, true); // a re-send of a stored batch stays stored
        assert_eq!(s.marks()[0].durable_below, 6, "refused batches are decided");
        let refused: Vec<u64> = (0..7).filter(|&q| s.refused(0, 9, q)).collect();
        assert_eq!(refused, [1, 2, 3, 4]);
        assert_eq!(s.refused[&(0, 9)], BTreeMap::from([(1, 5)]), "one range");
        assert!(!s.refused(1, 9, 1) && !s.refused(0, 8, 1));
        // A stream forgotten takes its refusals along.
        for stream in 10..10 + MAX_STREAM_MARKS as u64 {
            s.record(1, stream, 0);
        }
        assert!(!s.refused(0, 9, 1) && s.refused.is_empty());
    }

    #[test]
    fn the_stalest_stream_is_forgotten_past_the_limit() {
        let mut s = Streams::default();
        for stream in 1..=MAX_STREAM_MARKS as u64 {
            s.record(0, stream, 0);
        }
        s.record(0, 1, 1); // stream 1 is fresh again; stream 2 is now the stalest
        s.record(1, 1, 0);
        assert_eq!(s.len(), MAX_STREAM_MARKS);
        assert!(!s.seen(0, 2, 0) && s.seen(0, 1, 1) && s.seen(1, 1, 0));
    }
}
