//! The spool: every experience batch this executor publishes stays on disk until the replay server
//! says it is durable (`replay/durable`: stored or refused, and covered by a snapshot written after
//! that), and is sent again whenever a replay server (re)appears. With the replay server's dedupe of
//! re-sent batches, every produced transition ends in the buffer or in a counted reason.
//!
//! Layout of `<spool_dir>/executor-<id>/`:
//! - `<stream>-<seq>.batch` (both hex, fixed width): one encoded [`ExperienceBatch`] frame (CRC'd by
//!   `proto`), written to a temporary name and renamed, so a killed process leaves whole files;
//! - `ledger`: one appended line per batch and outcome, the account a fault soak adds up:
//!   `produced <stream> <seq> <transitions>` and `dropped <reason> <stream> <seq> <transitions>`,
//!   the reasons `invalid` (failed the wire checks: never sent), `spool_overflow` (the oldest past
//!   `spool_max_bytes`: sent, but no longer re-sent) and `spool_write` (its file could not be
//!   written: sent once, unspooled);
//! - `<stream>.made` (the stream in hex): one fixed-width decimal number, the transitions the
//!   rollout of that stream has made so far ([`MadeMark`]), rewritten in place by the rollout thread after every step that
//!   makes any, before they can reach a batch. What a killed process held in memory (its rollout's
//!   pending transitions, batches on their way to the spool) is the stream's mark less what the
//!   ledger names: the audit's "lost at kill", counted, never unexplained.
//!
//! A file is written before its `produced` line; a process killed in between leaves a file the
//! ledger does not name, and the next start adds its line. A ledger line that cannot be written is
//! kept and written before the next one (the spool counts them meanwhile). Files survive a killed
//! process, not a crashed machine (nothing is fsynced: that would cost a disk flush per batch).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::FileExt;
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
    /// Batches whose file could not be written: published once, unspooled (`dropped spool_write`).
    pub write_failed_batches: u64,
    /// Ledger lines not written yet (the ledger's disk failed); written before the next line.
    pub ledger_backlog: u64,
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
    /// Ledger lines a failed write left over, written before the next one.
    backlog: Vec<String>,
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
            backlog: Vec::new(),
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
                spool.note(format!("produced {:x} {} {transitions}", key.0, key.1));
            }
            let bytes = fs::metadata(&path)?.len();
            spool.held.insert(key, bytes);
            spool.counts.held_bytes += bytes;
        }
        spool.counts.held_batches = spool.held.len() as u64;
        Ok(spool)
    }

    /// The mark of the transitions `stream`'s rollout makes, starting at 0 (see [`MadeMark`]).
    pub fn made_mark(&self, stream: u64) -> io::Result<MadeMark> {
        let file = OpenOptions::new().create(true).write(true).truncate(true).open(self.made_path(stream))?;
        let mut mark = MadeMark { file, made: 0 };
        mark.write()?;
        Ok(mark)
    }

    /// Spools `batch` and returns its frame to publish; `None` when it fails the wire checks
    /// (counted and in the ledger as `dropped invalid`). A batch whose file cannot be written is
    /// published all the same, once and unspooled: counted, and in the ledger as `dropped
    /// spool_write` (the audit finds it stored if the replay server got it). Drops the oldest
    /// batches past the limit.
    pub fn push(&mut self, batch: &ExperienceBatch) -> Option<Vec<u8>> {
        let key = (batch.stream, batch.seq);
        let transitions = batch.len() as u64;
        if batch.validate().is_err() {
            self.counts.invalid_batches += 1;
            self.note(format!("dropped invalid {:x} {} {transitions}", key.0, key.1));
            return None;
        }
        let frame = proto::encode(batch);
        let path = self.path(key);
        let tmp = path.with_extension("tmp");
        if let Err(error) = fs::write(&tmp, &frame).and_then(|()| fs::rename(&tmp, &path)) {
            tracing::error!(%error, stream = key.0, seq = key.1, "could not spool a batch; sending it unspooled");
            let _ = fs::remove_file(&tmp);
            self.counts.write_failed_batches += 1;
            self.note(format!("dropped spool_write {:x} {} {transitions}", key.0, key.1));
            return Some(frame);
        }
        self.note(format!("produced {:x} {} {transitions}", key.0, key.1));
        self.counts.produced_batches += 1;
        self.counts.produced_transitions += transitions;
        self.hold(key, frame.len() as u64);
        while self.counts.held_bytes > self.max_bytes && self.held.len() > 1 {
            let Some((&oldest, _)) = self.held.first_key_value() else { break };
            let frame = fs::read(self.path(oldest)).unwrap_or_default();
            let n = decode(&frame).map_or(0, |b| b.len() as u64);
            // Its line first: a process killed in between leaves a batch the ledger calls dropped
            // and its next start sends again (stored, the audit says), never one gone unnamed.
            self.counts.overflow_batches += 1;
            self.note(format!("dropped spool_overflow {:x} {} {n}", oldest.0, oldest.1));
            if let Err(error) = self.release(oldest) {
                tracing::error!(%error, "could not drop the spool's oldest batch; the spool stays over its limit");
                break;
            }
        }
        Some(frame)
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

    fn made_path(&self, stream: u64) -> PathBuf {
        self.dir.join(format!("{stream:016x}.made"))
    }

    /// Appends `line` to the ledger, after any a failed write left over; on failure keeps them all
    /// for the next time (counted meanwhile). After a failure the text starts with a newline, so a
    /// line written in part ends there and is skipped as malformed.
    fn note(&mut self, line: String) {
        let after_failure = !self.backlog.is_empty();
        self.backlog.push(line);
        let mut text = String::from(if after_failure { "\n" } else { "" });
        for line in &self.backlog {
            text.push_str(line);
            text.push('\n');
        }
        match self.ledger.write_all(text.as_bytes()) {
            Ok(()) => self.backlog.clear(),
            Err(error) => {
                if !after_failure {
                    tracing::error!(%error, "could not write the spool's ledger; keeping its lines until it can");
                }
            }
        }
        self.counts.ledger_backlog = self.backlog.len() as u64;
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

/// What one executor's spool folder says: what an audit of a run adds up.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Ledger {
    /// The ledger's lines, in order.
    pub entries: Vec<LedgerEntry>,
    /// The batches the spool still holds, sorted.
    pub held: Vec<Key>,
    /// Per stream, the transitions its rollout made ([`MadeMark`]).
    pub made: BTreeMap<u64, u64>,
}

/// Executor `executor_id`'s ledger under `spool_dir` (empty if it never spooled), the batches its
/// spool still holds and its streams' made marks.
pub fn read_ledger(spool_dir: &Path, executor_id: u32) -> io::Result<Ledger> {
    let dir = spool_dir.join(format!("executor-{executor_id}"));
    let text = match fs::read_to_string(dir.join("ledger")) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Ledger::default()),
        Err(e) => return Err(e),
    };
    let mut ledger = Ledger { entries: text.lines().filter_map(parse_entry).collect(), ..Ledger::default() };
    for entry in fs::read_dir(&dir)? {
        let entry = entry?;
        let Some(name) = entry.file_name().to_str().map(str::to_string) else { continue };
        if let Some(key) = parse_name(&name) {
            ledger.held.push(key);
        } else if let Some(stream) = name.strip_suffix(".made") {
            let (Ok(stream), Ok(text)) = (u64::from_str_radix(stream, 16), fs::read_to_string(entry.path()))
            else {
                continue;
            };
            if let Ok(made) = text.trim().parse() {
                ledger.made.insert(stream, made);
            }
        }
    }
    ledger.held.sort_unstable();
    Ok(ledger)
}

/// The transitions one stream's rollout has made, on disk (`<stream>.made` in the spool's folder):
/// the rollout thread adds each step's before they can reach a batch, so at any moment, a SIGKILL
/// included, the mark is at least what the ledger names of the stream, and the difference is what
/// the process held in memory. Each [`MadeMark::add`] is one small write in place (no fsync: like
/// the spool, it survives a killed process, not a crashed machine).
#[derive(Debug)]
pub struct MadeMark {
    file: File,
    made: u64,
}

impl MadeMark {
    /// Adds `transitions` just made and writes the new total.
    pub fn add(&mut self, transitions: u64) -> io::Result<()> {
        self.made += transitions;
        self.write()
    }

    /// The total so far.
    pub fn made(&self) -> u64 {
        self.made
    }

    fn write(&mut self) -> io::Result<()> {
        // Fixed width: each write covers the last one whole.
        self.file.write_all_at(format!("{:020}\n", self.made).as_bytes(), 0)
    }
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
            let frame = spool.push(&batch(0xab, seq, 5)).unwrap();
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
        assert_eq!(spool.push(&bad), None);
        let c = spool.counts();
        assert_eq!((c.produced_batches, c.overflow_batches, c.invalid_batches, c.held_batches), (3, 1, 1, 2));
        assert_eq!(c.held_bytes, 2 * one);
        let lines = ledger(dir.path());
        assert!(lines.contains(&"dropped spool_overflow 1 0 4".to_string()), "{lines:?}");
        assert!(lines.contains(&"dropped invalid 1 3 4".to_string()), "{lines:?}");
        let Ledger { entries, held, made } = read_ledger(dir.path(), 3).unwrap();
        assert_eq!(held, [(1, 1), (1, 2)]);
        assert!(made.is_empty(), "no rollout marked this spool");
        assert_eq!(entries.len(), 5);
        let overflow =
            LedgerEntry { dropped: Some("spool_overflow".into()), stream: 1, seq: 0, transitions: 4 };
        assert!(entries.contains(&overflow));
        assert_eq!(entries.iter().filter(|e| e.dropped.is_none()).count(), 3);
    }

    #[test]
    fn a_batch_that_cannot_be_spooled_is_sent_counted_and_in_the_ledger() {
        let dir = tempfile::tempdir().unwrap();
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        spool.push(&batch(7, 0, 2)).unwrap();
        // The next batch's file cannot be written: a folder stands where it goes.
        let sub = dir.path().join("executor-3");
        fs::create_dir(sub.join(format!("{:016x}-{:012x}.tmp", 7, 1))).unwrap();
        let frame = spool.push(&batch(7, 1, 3)).expect("sent all the same, unspooled");
        assert_eq!(decode(&frame).unwrap(), batch(7, 1, 3));
        spool.push(&batch(7, 2, 4)).unwrap();
        let c = spool.counts();
        assert_eq!((c.produced_batches, c.write_failed_batches, c.held_batches), (2, 1, 2));
        assert_eq!(spool.held(), [(7, 0), (7, 2)], "not held: nothing to re-send");
        assert_eq!(ledger(dir.path()), ["produced 7 0 2", "dropped spool_write 7 1 3", "produced 7 2 4"]);
    }

    #[test]
    fn ledger_lines_a_failed_write_left_are_written_with_the_next_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        spool.push(&batch(7, 0, 2)).unwrap();
        // The ledger's disk fails (a read-only handle stands in for it), then recovers.
        let path = dir.path().join("executor-3/ledger");
        let writable = std::mem::replace(&mut spool.ledger, File::open(&path).unwrap());
        spool.push(&batch(7, 1, 3)).unwrap();
        assert_eq!(spool.counts().ledger_backlog, 1);
        spool.ledger = writable;
        spool.push(&batch(7, 2, 4)).unwrap();
        assert_eq!(spool.counts().ledger_backlog, 0);
        let lines = ledger(dir.path());
        assert_eq!(lines, ["produced 7 0 2", "", "produced 7 1 3", "produced 7 2 4"]);
        assert_eq!(read_ledger(dir.path(), 3).unwrap().entries.len(), 3);
    }

    #[test]
    fn made_marks_hold_each_streams_total_and_are_read_with_the_ledger() {
        let dir = tempfile::tempdir().unwrap();
        let spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        let mut mark = spool.made_mark(0xab).unwrap();
        assert_eq!(read_ledger(dir.path(), 3).unwrap().made, BTreeMap::from([(0xab, 0)]));
        for n in [5, 0, 1_000_000_007, 3] {
            mark.add(n).unwrap();
        }
        assert_eq!(mark.made(), 1_000_000_015);
        let mut other = spool.made_mark(0xcd).unwrap();
        other.add(2).unwrap();
        let read = read_ledger(dir.path(), 3).unwrap();
        assert_eq!(read.made, BTreeMap::from([(0xab, 1_000_000_015), (0xcd, 2)]));
        assert!(read.held.is_empty() && read.entries.is_empty());
        // A new process keeps the earlier marks: they are the account of the earlier streams.
        drop(spool);
        let spool = Spool::open(dir.path(), 3, 1 << 20).unwrap();
        assert!(spool.held().is_empty());
        assert_eq!(read_ledger(dir.path(), 3).unwrap().made.len(), 2);
    }
}
