//! Snapshots: the whole buffer (contents, priorities, counters) as one versioned, checksummed
//! byte stream to any `Write` and from any `Read`; the replay server puts it in its snapshot file.
//!
//! Format (version 3, little-endian): magic `RLREPLAY`, u32 version, then u64 obs_dim, act_dim,
//! capacity, observation rows, f64 α, ε, then u64 head, tail, rows written, evicted early,
//! sampled, updates applied, updates stale; then the arrays over the n = min(head, N) slots and
//! m = min(rows written, M) rows ever written (the rest of the rings are zero, as a new buffer's):
//! n f64 priorities, n × act_dim f32 actions, n f32 rewards, n u8 terminated, n u32 next-row
//! positions, m × obs_dim f32 rows; then the u32 CRC-32 (`crc32fast`, the checksum of every other
//! file and message of the project) of everything before it. Version 2, the same with whole rings
//! (a buffer filling up wrote mostly zeros: 480 MB for the Ant's first 74,000 transitions), is
//! still read; version 1 ended in a hand-rolled 64-bit checksum and is refused. Sizes follow from
//! the header, so a short stream fails with `UnexpectedEof` and a long one leaves its tail unread.
//!
//! Restoring rebuilds the sum tree from the leaves; since every node is a pure function of the
//! leaves (see `sum_tree`), the restored tree is bit-identical and sampling from it with the same
//! RNG seed gives the same batches. The sampling mode and β schedule come from the configuration
//! given at restore and may change; capacity, rows, α and ε shape the stored state and must match.

use std::io::{Read, Write};

use crate::buffer::ReplayBuffer;
use crate::config::{Dims, ReplayConfig};
use crate::error::SnapshotError;
use crate::storage::Storage;
use crate::sum_tree::SumTree;

/// First bytes of every snapshot.
pub const SNAPSHOT_MAGIC: [u8; 8] = *b"RLREPLAY";
/// The format version this build writes (it reads version 2 too).
pub const SNAPSHOT_VERSION: u32 = 3;
/// The last version that wrote whole rings.
const WHOLE_RINGS_VERSION: u32 = 2;

/// Values per encoded chunk: bounds the staging buffer at 128 KiB for any snapshot size.
const CHUNK: usize = 16 * 1024;

struct Encoder<'w, W: Write> {
    w: &'w mut W,
    sum: crc32fast::Hasher,
    staging: Vec<u8>,
}

impl<W: Write> Encoder<'_, W> {
    fn bytes(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.sum.update(bytes);
        self.w.write_all(bytes)
    }

    fn u64(&mut self, v: u64) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }

    fn array<T: Copy, const B: usize>(&mut self, values: &[T], enc: fn(T) -> [u8; B]) -> std::io::Result<()> {
        let mut staging = std::mem::take(&mut self.staging);
        for chunk in values.chunks(CHUNK) {
            staging.clear();
            chunk.iter().for_each(|&v| staging.extend_from_slice(&enc(v)));
            self.bytes(&staging)?;
        }
        self.staging = staging;
        Ok(())
    }
}

struct Decoder<'r, R: Read> {
    r: &'r mut R,
    sum: crc32fast::Hasher,
    staging: Vec<u8>,
}

impl<R: Read> Decoder<'_, R> {
    fn bytes<const B: usize>(&mut self) -> std::io::Result<[u8; B]> {
        let mut buf = [0; B];
        self.r.read_exact(&mut buf)?;
        self.sum.update(&buf);
        Ok(buf)
    }

    fn u64(&mut self) -> std::io::Result<u64> {
        self.bytes().map(u64::from_le_bytes)
    }

    fn array<T, const B: usize>(&mut self, out: &mut [T], dec: fn([u8; B]) -> T) -> std::io::Result<()> {
        let mut staging = std::mem::take(&mut self.staging);
        for chunk in out.chunks_mut(CHUNK) {
            staging.resize(chunk.len() * B, 0);
            self.r.read_exact(&mut staging)?;
            self.sum.update(&staging);
            for (v, b) in chunk.iter_mut().zip(staging.chunks_exact(B)) {
                let mut word = [0; B];
                word.copy_from_slice(b);
                *v = dec(word);
            }
        }
        self.staging = staging;
        Ok(())
    }
}

impl ReplayBuffer {
    /// Writes the buffer as a snapshot (see the module doc for the format). Wrap `w` in a
    /// `BufWriter` if it is unbuffered.
    pub fn write_snapshot<W: Write>(&self, w: &mut W) -> Result<(), SnapshotError> {
        self.write_snapshot_version(w, SNAPSHOT_VERSION)
    }

    /// Writes format `version` (this one, or version 2 for the tests that read it).
    fn write_snapshot_version<W: Write>(&self, w: &mut W, version: u32) -> Result<(), SnapshotError> {
        let s = &self.storage;
        let written = Written::of(s, version);
        let mut e = Encoder { w, sum: crc32fast::Hasher::new(), staging: Vec::new() };
        e.bytes(&SNAPSHOT_MAGIC)?;
        e.bytes(&version.to_le_bytes())?;
        for v in [s.dims.obs_dim as u64, s.dims.act_dim as u64, s.capacity as u64, s.row_capacity as u64] {
            e.u64(v)?;
        }
        e.u64(self.cfg.alpha.to_bits())?;
        e.u64(self.cfg.epsilon.to_bits())?;
        for v in [
            s.head,
            s.tail,
            s.rows_written,
            s.evicted_early,
            self.sampled_total,
            self.updates_applied,
            self.updates_stale,
        ] {
            e.u64(v)?;
        }
        let (n, m) = (written.slots, written.rows);
        let (act, obs) = (s.dims.act_dim, s.dims.obs_dim);
        e.array(&self.tree.leaf_values()[..n], f64::to_le_bytes)?;
        e.array(&s.actions[..n * act], f32::to_le_bytes)?;
        e.array(&s.rewards[..n], f32::to_le_bytes)?;
        e.array(&s.terminated[..n], |t| [u8::from(t)])?;
        e.array(&s.next_rows[..n], u32::to_le_bytes)?;
        e.array(&s.rows[..m * obs], f32::to_le_bytes)?;
        let checksum = std::mem::take(&mut e.sum).finalize();
        e.w.write_all(&checksum.to_le_bytes())?;
        e.w.flush()?;
        Ok(())
    }

    /// Restores a buffer written by [`write_snapshot`](Self::write_snapshot) for `cfg` and `dims`:
    /// the same transitions, priorities and counters. Rejects other formats, versions, dimensions
    /// and state-shaping settings with typed errors, and corrupt data by its checksum.
    pub fn read_snapshot<R: Read>(r: &mut R, cfg: ReplayConfig, dims: Dims) -> Result<Self, SnapshotError> {
        cfg.validate(dims)?;
        let mut d = Decoder { r, sum: crc32fast::Hasher::new(), staging: Vec::new() };
        if d.bytes()? != SNAPSHOT_MAGIC {
            return Err(SnapshotError::BadMagic);
        }
        let version = u32::from_le_bytes(d.bytes()?);
        if version != SNAPSHOT_VERSION && version != WHOLE_RINGS_VERSION {
            return Err(SnapshotError::UnsupportedVersion { found: version, supported: SNAPSHOT_VERSION });
        }
        let (obs_dim, act_dim) = (d.u64()?, d.u64()?);
        if (obs_dim, act_dim) != (dims.obs_dim as u64, dims.act_dim as u64) {
            let found = Dims { obs_dim: obs_dim as usize, act_dim: act_dim as usize };
            return Err(SnapshotError::DimsMismatch { expected: dims, found });
        }
        let mut storage = Storage::new(cfg.capacity_transitions, cfg.observation_rows_resolved(), dims);
        expect("capacity_transitions", storage.capacity as u64, d.u64()?)?;
        expect("observation_rows", storage.row_capacity as u64, d.u64()?)?;
        let alpha = f64::from_bits(d.u64()?);
        let epsilon = f64::from_bits(d.u64()?);
        if alpha.to_bits() != cfg.alpha.to_bits() {
            return Err(mismatch("alpha", cfg.alpha, alpha));
        }
        if epsilon.to_bits() != cfg.epsilon.to_bits() {
            return Err(mismatch("epsilon", cfg.epsilon, epsilon));
        }
        let mut counters = [0u64; 7];
        for c in &mut counters {
            *c = d.u64()?;
        }
        let [head, tail, rows_written, evicted_early, sampled_total, updates_applied, updates_stale] =
            counters;
        (storage.head, storage.rows_written) = (head, rows_written);
        let written = Written::of(&storage, version);
        let (n, m) = (written.slots, written.rows);
        let (act, obs) = (dims.act_dim, dims.obs_dim);
        let mut priorities = vec![0.0; storage.capacity];
        d.array(&mut priorities[..n], f64::from_le_bytes)?;
        d.array(&mut storage.actions[..n * act], f32::from_le_bytes)?;
        d.array(&mut storage.rewards[..n], f32::from_le_bytes)?;
        d.array(&mut storage.terminated[..n], |[b]| b != 0)?;
        d.array(&mut storage.next_rows[..n], u32::from_le_bytes)?;
        d.array(&mut storage.rows[..m * obs], f32::from_le_bytes)?;
        let expected_sum = std::mem::take(&mut d.sum).finalize();
        let mut found = [0; 4];
        d.r.read_exact(&mut found)?;
        if u32::from_le_bytes(found) != expected_sum {
            return Err(SnapshotError::ChecksumMismatch);
        }
        (storage.tail, storage.evicted_early) = (tail, evicted_early);
        check_invariants(&storage, &priorities)?;
        let mut tree = SumTree::new(storage.capacity);
        tree.fill(0, &priorities);
        let mut buffer = ReplayBuffer::from_parts(cfg, storage, tree);
        (buffer.sampled_total, buffer.updates_applied, buffer.updates_stale) =
            (sampled_total, updates_applied, updates_stale);
        Ok(buffer)
    }
}

/// How much of the rings a snapshot holds: the slots and rows ever written (all of them in
/// version 2). Nothing past them was ever written, so they are zero, as in a new buffer.
struct Written {
    slots: usize,
    rows: usize,
}

impl Written {
    fn of(s: &Storage, version: u32) -> Self {
        if version == WHOLE_RINGS_VERSION {
            return Self { slots: s.capacity, rows: s.row_capacity };
        }
        let prefix = |written: u64, ring: usize| usize::try_from(written).map_or(ring, |w| w.min(ring));
        Self { slots: prefix(s.head, s.capacity), rows: prefix(s.rows_written, s.row_capacity) }
    }
}

fn expect(field: &'static str, expected: u64, found: u64) -> Result<(), SnapshotError> {
    if expected == found { Ok(()) } else { Err(mismatch(field, expected, found)) }
}

fn mismatch(field: &'static str, expected: impl ToString, found: impl ToString) -> SnapshotError {
    SnapshotError::ConfigMismatch { field, expected: expected.to_string(), found: found.to_string() }
}

/// The checksum catches accidents; these catch a well-formed stream whose contents would break the
/// buffer (and would otherwise panic on an index later).
fn check_invariants(s: &Storage, priorities: &[f64]) -> Result<(), SnapshotError> {
    if s.tail > s.head || s.head - s.tail > s.capacity as u64 {
        return Err(SnapshotError::Corrupt("live range larger than the ring"));
    }
    if s.head > s.tail && s.rows_written < 2 {
        return Err(SnapshotError::Corrupt("live transitions without observation rows"));
    }
    if s.next_rows.iter().any(|&r| r as usize >= s.row_capacity) {
        return Err(SnapshotError::Corrupt("row position outside the observation rows"));
    }
    let consistent = priorities
        .iter()
        .enumerate()
        .all(|(slot, &p)| if s.occupant(slot).is_some() { p.is_finite() && p > 0.0 } else { p == 0.0 });
    if !consistent {
        return Err(SnapshotError::Corrupt("priorities disagree with the live transitions"));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
