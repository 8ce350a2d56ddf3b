//! The spool: every experience batch this executor publishes stays on disk until the replay server
//! says it is durable (`replay/durable`: stored or refused, and covered by a snapshot written after
//! that), and is sent again whenever a replay server (re)appears. With the replay server's dedupe of
//! re-sent batches, every produced transition ends in the buffer or in a counted reason.
//!
//! Layout of `<spool_dir>/executor-<id>/`:
//! - `<stream>-<seq>.batch` (both hex, fixed width): one encoded [`ExperienceBatch`] frame (CRC'd by
//!   `proto`), written to a temporary name and renamed, so a killed process leaves whole files;
//! - `ledger`: one appended line per batch and outcome, the account a fault soak adds up:
//!   `produced <stream> <seq> <transitions>` and `dropped <reason> <stream> <seq> <transitions>`.
//!
//! A file is written before its `produced` line; a process killed in between leaves a file the
//! ledger does not name, and the next start adds its line. Files survive a killed process, not a
//! crashed machine (nothing is fsynced: that would cost a disk flush per batch).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use proto::{DurableMarks, ExperienceBatch, Message};

/// A spooled batch: (stream, seq).
pub type Key = (u64, u64);

/// Figures of the spool, since this process started.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct SpoolCounts {
    /// Batches and transitions spooled (produced) by this process.
    pub produced_batches: u64,
    /// Transitions in them.
    pub produced_transitions: u64,
    /// Batches released because the replay server made them durable.
    pub durable_batches: u64,
    /// Batches sent again after a replay server appeared.
    pub resent_batches: u64,
    /// Batches dropped, oldest first, to keep the spool within `spool_max_bytes`.
    pub overflow_batches: u64,
    /// Batches dropped because they failed the wire checks (non-finite TD errors).
    pub invalid_batches: u64,
    /// Batches held now.
    pub held_batches: u64,
    /// Bytes held now.
    pub held_bytes: u64,
}

/// The on-disk spool of one executor.
#[derive(Debug)]
pub struct Spool {
    dir: PathBuf,
    executor_id: u32,
    max_bytes: u64,
    held: BTreeMap<Key, u64>,
    ledger: File,
    counts: SpoolCounts,
    /// Per stream, the durable prefix the last marks gave and their snapshot's number.
    prefixes: BTreeMap<u64, (u64, u64)>,
}

/// What one [`DurableMarks`] did to the spool.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Released {
    /// Batches released as durable.
    pub durable: u64,
    /// Held batches at which a stream's durable prefix has not moved across two snapshots: lost on
    /// the way (the replay server stores a stream's batches in order, so the ones after it are
    /// waiting on it) and to be sent again. A slow one sent twice is stored once.
    pub stalled: Vec<Key>,
}

impl Spool {
    /// Opens (creating) executor `executor_id`'s spool under `root`, taking over what earlier runs
    /// of it left: their batches are held (to be re-sent) and the ledger completed.
    pub fn open(root: &Path, executor_id: u32, max_bytes: u64) -> io::Result<Self> {
        let dir = root.join(format!("executor-{executor_id}"));
        fs::create_dir_all(&dir)?;
        let ledgered = read_produced(&dir.join("ledger"))?;
        let ledger = OpenOptions::new().create(true).append(true).open(dir.join("ledger"))?;
        let mut spool = Self {
            dir,
            executor_id,
            max_bytes,
            held: BTreeMap::new(),
            ledger,
            counts: SpoolCounts::default(),
            prefixes: BTreeMap::new(),
        };
        for entry in fs::read_dir(&spool.dir)? {
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if name.ends_with(".tmp") {
                fs::remove_file(&path)?; // a write the process did not finish: never produced
                continue;
            }
            let Some(key) = parse_name(name) else { continue };
            if !ledgered.contains(&key) {
                // Written, then killed before its ledger line.
                let transitions = decode(&fs::read(&path)?).map_or(0, |b| b.len() as u64);
                writeln!(spool.ledger, "produced {:x} {} {transitions}", key.0, key.1)?;
            }
            let bytes = fs::metadata(&path)?.len();
            spool.held.insert(key, bytes);
            spool.counts.held_bytes += bytes;
        }
        spool.counts.held_batches = spool.held.len() as u64;
        Ok(spool)
    }

    /// Spools `batch` and returns its frame to publish; `None` when it fails the wire checks
    /// (counted and in the ledger as `dropped invalid`). Drops the oldest batches past the limit.
    pub fn push(&mut self, batch: &ExperienceBatch) -> io::Result<Option<Vec<u8>>> {
        let key = (batch.stream, batch.seq);
        let transitions = batch.len() as u64;
        if batch.validate().is_err() {
            self.counts.invalid_batches += 1;
            writeln!(self.ledger, "dropped invalid {:x} {} {transitions}", key.0, key.1)?;
            return Ok(None);
        }
        let frame = proto::encode(batch);
        let path = self.path(key);
        let tmp = path.with_extension("tmp");
        fs::write(&tmp, &frame)?;
        fs::rename(&tmp, &path)?;
        writeln!(self.ledger, "produced {:x} {} {transitions}", key.0, key.1)?;
        self.counts.produced_batches += 1;
        self.counts.produced_transitions += transitions;
        self.hold(key, frame.len() as u64);
        while self.counts.held_bytes > self.max_bytes && self.held.len() > 1 {
            let Some((&oldest, _)) = self.held.first_key_value() else { break };
            let frame = fs::read(self.path(oldest)).unwrap_or_default();
            let n = decode(&frame).map_or(0, |b| b.len() as u64);
            self.release(oldest)?;
            self.counts.overflow_batches += 1;
            writeln!(self.ledger, "dropped spool_overflow {:x} {} {n}", oldest.0, oldest.1)?;
        }
        Ok(Some(frame))
    }

    /// Releases every held batch of this executor that `marks` says is durable, and finds the
    /// batches its streams' prefixes are stalled at.
    pub fn on_marks(&mut self, marks: &DurableMarks) -> io::Result<Released> {
        let id = self.executor_id;
        let durable: Vec<Key> = self
            .held
            .keys()
            .filter(|(stream, seq)| marks.durable_below(id, *stream).is_some_and(|b| *seq < b))
            .copied()
            .collect();
        for key in &durable {
            self.release(*key)?;
        }
        self.counts.durable_batches += durable.len() as u64;
        let mut stalled = Vec::new();
        for mark in marks.marks.iter().filter(|m| m.executor_id == id) {
            let now = (mark.durable_below, marks.snapshot_sequence);
            let before = self.prefixes.insert(mark.stream, now);
            let key = (mark.stream, mark.durable_below);
            // The same prefix in a later snapshot, and its next batch is one we sent.
            if before.is_some_and(|(below, sequence)| below == now.0 && sequence < now.1)
                && self.held.contains_key(&key)
            {
                stalled.push(key);
            }
        }
        Ok(Released { durable: durable.len() as u64, stalled })
    }

    /// The batches held, oldest first (what a re-send sends).
    pub fn held(&self) -> Vec<Key> {
        self.held.keys().copied().collect()
    }

    /// The frame of held batch `key` for a re-send (counted); `None` if it is gone meanwhile.
    pub fn resend(&mut self, key: Key) -> Option<Vec<u8>> {
        let frame = fs::read(self.path(key)).ok()?;
        self.counts.resent_batches += 1;
        Some(frame)
    }

    /// Figures since start, and what is held now.
    pub fn counts(&self) -> SpoolCounts {
        self.counts
    }

    fn path(&self, (stream, seq): Key) -> PathBuf {
        self.dir.join(format!("{stream:016x}-{seq:012x}.batch"))
    }

    fn hold(&mut self, key: Key, bytes: u64) {
        if self.held.insert(key, bytes).is_none() {
            self.counts.held_bytes += bytes;
        }
        self.counts.held_batches = self.held.len() as u64;
    }

    fn release(&mut self, key: Key) -> io::Result<()> {
        if let Some(bytes) = self.held.remove(&key) {
            self.counts.held_bytes -= bytes;
            match fs::remove_file(self.path(key)) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        self.counts.held_batches = self.held.len() as u64;
        Ok(())
    }
}

/// One line of a spool's ledger.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LedgerEntry {
    /// `None` for `produced`; the reason for `dropped <reason>`.
    pub dropped: Option<String>,
    /// The batch's stream.
    pub stream: u64,
    /// Its number in the stream.
    pub seq: u64,
    /// Transitions in it.
    pub transitions: u64,
}

/// Executor `executor_id`'s ledger under `spool_dir` (empty if it never spooled), and the batches
/// its spool still holds: what an audit of a run adds up.
pub fn read_ledger(spool_dir: &Path, executor_id: u32) -> io::Result<(Vec<LedgerEntry>, Vec<Key>)> {
    let dir = spool_dir.join(format!("executor-{executor_id}"));
    let text = match fs::read_to_string(dir.join("ledger")) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok((Vec::new(), Vec::new())),
        Err(e) => return Err(e),
    };
    let entries = text.lines().filter_map(parse_entry).collect();
    let mut held = Vec::new();
    for entry in fs::read_dir(&dir)? {
        if let Some(key) = entry?.file_name().to_str().and_then(parse_name) {
            held.push(key);
        }
    }
    held.sort_unstable();
    Ok((entries, held))
}

fn parse_entry(line: &str) -> Option<LedgerEntry> {
    let words: Vec<&str> = line.split(' ').collect();
    let (dropped, rest) = match words.as_slice() {
        ["produced", rest @ ..] => (None, rest),
        ["dropped", reason, rest @ ..] => (Some(reason.to_string()), rest),
        _ => return None,
    };
    let [stream, seq, n] = rest else { return None };
    Some(LedgerEntry {
        dropped,
        stream: u64::from_str_radix(stream, 16).ok()?,
        seq: seq.parse().ok()?,
        transitions: n.parse().ok()?,
    })
}

fn decode(frame: &[u8]) -> Option<ExperienceBatch> {
    proto::decode::<ExperienceBatch>(frame).ok()
}

/// `<stream hex>-<seq hex>.batch` → key.
fn parse_name(name: &str) -> Option<Key> {
    let (stream, seq) = name.strip_suffix(".batch")?.split_once('-')?;
    Some((u64::from_str_radix(stream, 16).ok()?, u64::from_str_radix(seq, 16).ok()?))
}

/// The batches a ledger names as produced.
fn read_produced(path: &Path) -> io::Result<BTreeSet<Key>> {
    let text = match fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(BTreeSet::new()),
        Err(e) => return Err(e),
    };
    let produced = text.lines().filter_map(parse_entry).filter(|e| e.dropped.is_none());
    Ok(produced.map(|e| (e.stream, e.seq)).collect())
}

#[cfg(test)]
mod tests {
    use proto::{StreamMark, Transitions};

    use super::*;

    fn batch(stream: u64, seq: u64, n: usize) -> ExperienceBatch {
        let mut transitions = Transitions::with_capacity(2, 1, n);
        for i in 0..n {
            let x = i as f32;
            transitions
                .push(proto::Transition {
                    observation: &[x, x],
                    action: &[0.5],
                    reward: 1.0,
                    next_observation: &[x + 1.0, x],
                    terminated: false,
                })
                .unwrap();
        }
        ExperienceBatch {
            executor_id: 3,
            stream,
            seq,
            weights_version: 0,
            env_steps: seq,
            transitions,
            td_errors: vec![0.5; n],
        }
    }

    fn marks(stream: u64, durable_below: u64) -> DurableMarks {
        DurableMarks {
            snapshot_sequence: 1,
            marks: vec![StreamMark { executor_id: 3, stream, durable_below }],
        }
    }

    fn ledger(dir: &Path) -> Vec<String> {
        fs::read_to_string(dir.join("executor-3/ledger")).unwrap().lines().map(str::to_string).collect()
    }

    #[test]
    fn batches_stay_until_durable_and_survive_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        for seq in 0..4 {
            let frame = spool.push(&batch(0xab, seq, 5)).unwrap().unwrap();
            assert_eq!(decode(&frame).unwrap().seq, seq);
        }
        assert_eq!(spool.on_marks(&marks(0xab, 2)).unwrap().durable, 2);
        assert_eq!(spool.on_marks(&marks(0xcd, 9)).unwrap().durable, 0, "another stream's marks");
        assert_eq!(spool.held(), [(0xab, 2), (0xab, 3)]);
        drop(spool);

        // A new process takes over: the earlier stream's undurable batches are held for a re-send.
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        assert_eq!(spool.held(), [(0xab, 2), (0xab, 3)]);
        let frame = spool.resend((0xab, 3)).unwrap();
        assert_eq!(decode(&frame).unwrap(), batch(0xab, 3, 5));
        assert_eq!(ledger(dir.path()).len(), 4, "one produced line per batch, none added at reopening");
        assert_eq!(ledger(dir.path())[0], "produced ab 0 5");
    }

    #[test]
    fn a_prefix_that_stalls_across_snapshots_names_the_batch_it_waits_on() {
        let dir = tempfile::tempdir().unwrap();
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        for seq in 0..5 {
            spool.push(&batch(7, seq, 2)).unwrap();
        }
        let at = |sequence, below| DurableMarks { snapshot_sequence: sequence, ..marks(7, below) };
        assert_eq!(spool.on_marks(&at(1, 1)).unwrap(), Released { durable: 1, stalled: vec![] });
        // The same marks again (re-published between snapshots): not a stall.
        assert_eq!(spool.on_marks(&at(1, 1)).unwrap().stalled, []);
        // A later snapshot with the prefix still at 1 while 2.. were sent: batch 1 was lost.
        assert_eq!(spool.on_marks(&at(2, 1)).unwrap().stalled, [(7, 1)]);
        // Sent again and stored, the prefix jumps past the batches that waited on it.
        assert_eq!(spool.on_marks(&at(3, 5)).unwrap(), Released { durable: 4, stalled: vec![] });
        // An executor with nothing more to send (at the barrier) holds no batch at its prefix.
        assert_eq!(spool.on_marks(&at(4, 5)).unwrap().stalled, []);
    }

    #[test]
    fn a_file_without_its_ledger_line_is_produced_at_the_next_start() {
        let dir = tempfile::tempdir().unwrap();
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        spool.push(&batch(7, 0, 2)).unwrap();
        drop(spool);
        // As if killed between the rename and the ledger line, and during another write.
        let sub = dir.path().join("executor-3");
        fs::write(sub.join(format!("{:016x}-{:012x}.batch", 7, 1)), proto::encode(&batch(7, 1, 3))).unwrap();
        fs::write(sub.join("half.tmp"), b"partial").unwrap();
        let spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        assert_eq!(spool.held(), [(7, 0), (7, 1)]);
        assert_eq!(ledger(dir.path()), ["produced 7 0 2", "produced 7 1 3"]);
        assert!(!sub.join("half.tmp").exists());
    }

    #[test]
    fn overflow_and_invalid_batches_are_dropped_and_accounted() {
        let dir = tempfile::tempdir().unwrap();
        let one = proto::encode(&batch(1, 0, 4)).len() as u64;
        let mut spool = Spool::open(dir.path(), 3, 2 * one).unwrap();
        for seq in 0..3 {
            spool.push(&batch(1, seq, 4)).unwrap();
        }
        assert_eq!(spool.held(), [(1, 1), (1, 2)], "the oldest went");
        let mut bad = batch(1, 3, 4);
        bad.td_errors[0] = f32::NAN;
        assert_eq!(spool.push(&bad).unwrap(), None);
        let c = spool.counts();
        assert_eq!((c.produced_batches, c.overflow_batches, c.invalid_batches, c.held_batches), (3, 1, 1, 2));
        assert_eq!(c.held_bytes, 2 * one);
        let lines = ledger(dir.path());
        assert!(lines.contains(&"dropped spool_overflow 1 0 4".to_string()), "{lines:?}");
        assert!(lines.contains(&"dropped invalid 1 3 4".to_string()), "{lines:?}");
        let (entries, held) = read_ledger(dir.path(), 3).unwrap();
        assert_eq!(held, [(1, 1), (1, 2)]);
        assert_eq!(entries.len(), 5);
        let overflow =
            LedgerEntry { dropped: Some("spool_overflow".into()), stream: 1, seq: 0, transitions: 4 };
        assert!(entries.contains(&overflow));
        assert_eq!(entries.iter().filter(|e| e.dropped.is_none()).count(), 3);
    }
}
