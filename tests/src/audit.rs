//! The account of a run's experience: every stream's made mark and every batch its executor's spool
//! ledger names, set against what the replay server decided (its stream table, from its report or
//! its final snapshot). Each transition a rollout made is stored (in the buffer, or evicted by FIFO
//! since), refused by the replay server (decided, never stored), dropped by the executor for the
//! reason its ledger gives, still pending in a spool (a restarted executor sends it again), or lost
//! at a kill: made (the mark says so) but in the killed process's memory, never in a spooled batch.
//! Anything else is unexplained, and [`Audit::check`] fails.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use replay_server::Streams;

/// The run's experience, added up, in transitions.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Audit {
    /// Batches the ledgers name.
    pub produced_batches: u64,
    /// Transitions the rollouts made: per stream its made mark, or what its ledger names should
    /// that be more (then [`Audit::unmarked`] says by how much).
    pub produced: u64,
    /// Decided by the replay server and stored (and perhaps evicted by FIFO since).
    pub stored: u64,
    /// Decided by the replay server and refused (wrong dimensions, too large, …: its rejection
    /// counters say why); never stored.
    pub refused: u64,
    /// Dropped by executors, by the ledger's reason (`spool_overflow`, `invalid`, `spool_write`).
    pub dropped: BTreeMap<String, u64>,
    /// Still in a spool, not yet decided.
    pub pending: u64,
    /// Made but in no ledgered batch: in memory (the rollout's pending transitions, batches on
    /// their way to the spool) when the process was killed. Each stream's made mark less its
    /// ledger's transitions.
    pub lost_at_kill: u64,
    /// Streams that lost any at a kill.
    pub killed_streams: u64,
    /// The most one stream lost at a kill (bounded by what an executor holds in memory:
    /// `(executor::OUT_QUEUE + 2) × batch_transitions` and one step's transitions).
    pub lost_at_kill_max: u64,
    /// Unexplained: batches a ledger names that were neither decided, nor dropped, nor held. Must
    /// be 0.
    pub lost: u64,
    /// Unexplained: transitions a ledger names past its stream's made mark (or of a stream without
    /// one). Must be 0.
    pub unmarked: u64,
}

impl Audit {
    /// Whether every produced transition is explained: `produced = stored + refused + dropped +
    /// pending + lost_at_kill`, with nothing lost and nothing ledgered past a made mark.
    pub fn check(&self) -> Result<(), String> {
        let dropped: u64 = self.dropped.values().sum();
        let explained = self.stored + self.refused + dropped + self.pending + self.lost_at_kill;
        if self.lost == 0 && self.unmarked == 0 && explained == self.produced {
            return Ok(());
        }
        Err(format!(
            "unexplained experience: produced {} ≠ stored {} + refused {} + dropped {dropped} + pending {} + \
             lost at kill {} (= {explained}); {} transitions in batches neither decided, dropped nor held, {} \
             ledgered past their stream's made mark",
            self.produced,
            self.stored,
            self.refused,
            self.pending,
            self.lost_at_kill,
            self.lost,
            self.unmarked
        ))
    }
}

/// Audits the spools of `executors` under `spool_dir` against the replay server's `streams`.
pub fn audit(
    spool_dir: &Path,
    executors: impl IntoIterator<Item = u32>,
    streams: &Streams,
) -> std::io::Result<Audit> {
    let mut audit = Audit::default();
    for id in executors {
        let ledger = executor::read_ledger(spool_dir, id)?;
        // Per batch: its transitions and the executor's reason for dropping it, if it did.
        let mut batches: BTreeMap<(u64, u64), (u64, Option<String>)> = BTreeMap::new();
        for entry in ledger.entries {
            let batch = batches.entry((entry.stream, entry.seq)).or_insert((entry.transitions, None));
            if entry.dropped.is_some() {
                batch.1 = entry.dropped;
            }
        }
        let mut ledgered: BTreeMap<u64, u64> = BTreeMap::new();
        for ((stream, seq), (n, dropped)) in batches {
            audit.produced_batches += 1;
            *ledgered.entry(stream).or_default() += n;
            if streams.refused(id, stream, seq) {
                audit.refused += n;
            } else if streams.seen(id, stream, seq) {
                audit.stored += n;
            } else if let Some(reason) = dropped {
                *audit.dropped.entry(reason).or_default() += n;
            } else if ledger.held.binary_search(&(stream, seq)).is_ok() {
                audit.pending += n;
            } else {
                audit.lost += n;
            }
        }
        let all: BTreeSet<u64> = ledgered.keys().chain(ledger.made.keys()).copied().collect();
        for stream in all {
            let ledgered = ledgered.get(&stream).copied().unwrap_or(0);
            match ledger.made.get(&stream) {
                Some(&made) if made >= ledgered => {
                    audit.produced += made;
                    let lost = made - ledgered;
                    audit.lost_at_kill += lost;
                    audit.killed_streams += u64::from(lost > 0);
                    audit.lost_at_kill_max = audit.lost_at_kill_max.max(lost);
                }
                made => {
                    audit.produced += ledgered;
                    audit.unmarked += ledgered - made.copied().unwrap_or(0);
                }
            }
        }
    }
    Ok(audit)
}

#[cfg(test)]
mod tests {
    use std::fs;
    use std::path::PathBuf;

    use super::*;

    /// A spool folder for executor 0 with `ledger` lines, held batch files and made marks.
    fn spool(name: &str, ledger: &[&str], held: &[(u64, u64)], made: &[(u64, u64)]) -> PathBuf {
        let root = std::env::temp_dir().join(format!("audit-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&root);
        let dir = root.join("executor-0");
        fs::create_dir_all(&dir).unwrap();
        fs::write(dir.join("ledger"), ledger.iter().map(|l| format!("{l}\n")).collect::<String>()).unwrap();
        for (stream, seq) in held {
            fs::write(dir.join(format!("{stream:016x}-{seq:012x}.batch")), b"").unwrap();
        }
        for (stream, n) in made {
            fs::write(dir.join(format!("{stream:016x}.made")), format!("{n:020}\n")).unwrap();
        }
        root
    }

    const LEDGER: &[&str] = &[
        "produced a 0 4",
        "produced a 1 5",
        "produced a 2 6",
        "dropped invalid a 3 7",
        "produced a 4 8",
        "dropped spool_write a 5 9",
    ];

    #[test]
    fn every_transition_is_stored_refused_dropped_pending_or_lost_at_a_kill() {
        let root = spool("explained", LEDGER, &[(0xa, 4)], &[(0xa, 4 + 5 + 6 + 7 + 8 + 9 + 3), (0xb, 2)]);
        let mut streams = Streams::default();
        streams.decide(0, 0xa, 0, false);
        streams.decide(0, 0xa, 1, true);
        streams.decide(0, 0xa, 2, false);
        let audit = audit(&root, [0], &streams).unwrap();
        assert_eq!((audit.produced_batches, audit.produced), (6, 39 + 3 + 2));
        assert_eq!((audit.stored, audit.refused, audit.pending), (4 + 6, 5, 8), "refused is not stored");
        assert_eq!(audit.dropped, BTreeMap::from([("invalid".into(), 7), ("spool_write".into(), 9)]));
        // Stream a's process was killed holding 3 made transitions; stream b's before any batch.
        assert_eq!((audit.lost_at_kill, audit.killed_streams, audit.lost_at_kill_max), (5, 2, 3));
        assert_eq!((audit.lost, audit.unmarked), (0, 0));
        assert_eq!(audit.check(), Ok(()));
        fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn a_difference_nothing_explains_fails_the_audit() {
        let mut streams = Streams::default();
        streams.decide(0, 0xa, 0, false);
        // Batch 1 was neither decided, nor dropped, nor held.
        let root = spool("lost", &LEDGER[..2], &[], &[(0xa, 9)]);
        let audit = audit(&root, [0], &streams).unwrap();
        assert_eq!((audit.stored, audit.lost), (4, 5));
        assert!(audit.check().is_err(), "{audit:?}");
        // A ledger past its made mark, and a stream without one.
        let root = spool("unmarked", &["produced a 0 4", "produced c 0 3"], &[], &[(0xa, 1)]);
        let mut streams = Streams::default();
        streams.decide(0, 0xa, 0, false);
        streams.decide(0, 0xc, 0, false);
        let audit = super::audit(&root, [0], &streams).unwrap();
        assert_eq!((audit.produced, audit.stored, audit.unmarked, audit.lost_at_kill), (7, 7, 3 + 3, 0));
        assert!(audit.check().unwrap_err().contains("6 ledgered past"), "{audit:?}");
        fs::remove_dir_all(root).unwrap();
        fs::remove_dir_all(std::env::temp_dir().join(format!("audit-lost-{}", std::process::id()))).unwrap();
    }
}
