//! The account of a run's experience: every batch an executor's spool ledger names, set against
//! what the replay server decided (its stream table, from its report or its final snapshot). Each
//! batch is stored (in the buffer, or evicted by FIFO since), dropped by the executor for the
//! reason its ledger gives, still pending in a spool (a restarted executor sends it again), or lost.

use std::collections::BTreeMap;
use std::path::Path;

use replay_server::Streams;

/// The run's experience, added up, in transitions.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Audit {
    /// Batches the ledgers name.
    pub produced_batches: u64,
    /// Transitions in them.
    pub produced: u64,
    /// Decided by the replay server: stored (and perhaps evicted by FIFO since).
    pub stored: u64,
    /// Dropped by executors, by the ledger's reason (`spool_overflow`, `invalid`).
    pub dropped: BTreeMap<String, u64>,
    /// Still in a spool, not yet decided.
    pub pending: u64,
    /// Neither decided, nor dropped, nor held: lost. Must be 0.
    pub lost: u64,
}

/// Audits the spools of `executors` under `spool_dir` against the replay server's `streams`.
pub fn audit(
    spool_dir: &Path,
    executors: impl IntoIterator<Item = u32>,
    streams: &Streams,
) -> std::io::Result<Audit> {
    let mut audit = Audit::default();
    for id in executors {
        let (entries, held) = executor::read_ledger(spool_dir, id)?;
        // Per batch: its transitions and the executor's reason for dropping it, if it did.
        let mut batches: BTreeMap<(u64, u64), (u64, Option<String>)> = BTreeMap::new();
        for entry in entries {
            let batch = batches.entry((entry.stream, entry.seq)).or_insert((entry.transitions, None));
            if entry.dropped.is_some() {
                batch.1 = entry.dropped;
            }
        }
        for ((stream, seq), (n, dropped)) in batches {
            audit.produced_batches += 1;
            audit.produced += n;
            if streams.seen(id, stream, seq) {
                audit.stored += n;
            } else if let Some(reason) = dropped {
                *audit.dropped.entry(reason).or_default() += n;
            } else if held.binary_search(&(stream, seq)).is_ok() {
                audit.pending += n;
            } else {
                audit.lost += n;
            }
        }
    }
    Ok(audit)
}
