//! Snapshot files: the server's own state (a [`Sidecar`]: counters, rejections, limiter, sequence)
//! followed by the replay buffer's snapshot, in one file, so one rename publishes both together.
//!
//! ```text
//! offset  size  field
//!      0     8  magic b"RLRSERVE"
//!      8     4  SERVER_SNAPSHOT_VERSION, u32 little-endian
//!     12     4  sidecar length, u32 little-endian
//!     16     4  CRC32 of the sidecar
//!     20     …  sidecar: bincode 2, config::standard()
//!      …     …  replay::ReplayBuffer::write_snapshot (versioned and checksummed by `replay`)
//! ```
//!
//! Writing is split so that the buffer being written is needed only while bytes are produced: the
//! serialisation to a temporary file beside `<path>` ([`FileWriter::write`]) is followed, on a helper
//! thread, by [`node::durable::publish`]: fsync, rename over `<path>`, fsync of the directory. A crash
//! leaves the previous or the new file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use node::durable;
use replay::{Dims, ReplayBuffer, ReplayConfig};
use serde::{Deserialize, Serialize};

use crate::limiter::{LimiterConfig, LimiterCounters};
use crate::service::ServiceCounters;
use crate::streams::{Streams, StreamsV3};

/// First bytes of a server snapshot.
pub const SERVER_SNAPSHOT_MAGIC: [u8; 8] = *b"RLRSERVE";
/// Format version of the server part; the buffer part carries `replay::SNAPSHOT_VERSION`.
pub const SERVER_SNAPSHOT_VERSION: u32 = 4;
/// Largest sidecar read back: it holds counters and rejection reasons, a few KiB at most.
const MAX_SIDECAR_BYTES: u32 = 1 << 26;

/// The server's state beside the buffer, saved with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Snapshot number, 1 for the first ever written by this run.
    pub sequence: u64,
    /// When the state was captured, Unix milliseconds.
    pub unix_ms: u64,
    /// The service's counters.
    pub counters: ServiceCounters,
    /// Rejections by reason.
    pub rejected: BTreeMap<String, u64>,
    /// The limiter's configuration when saved (a change resets the limiter's epoch on restore).
    pub limiter_config: LimiterConfig,
    /// The limiter's counters.
    pub limiter: LimiterCounters,
    /// The sampling seed in use (informational: the configured seed wins on restore).
    pub seed: u64,
    /// Decided batches per executor stream, as of the buffer saved with this sidecar: what the
    /// snapshot makes durable ([`proto::DurableMarks`]).
    pub streams: Streams,
    /// Deterministic mode's state at the cut this snapshot is (`None` in normal mode).
    pub lockstep: Option<crate::lockstep::Saved>,
}

/// Version 3's sidecar (before the streams table told refused batches apart), read and upgraded;
/// version 2's is version 3's without the trailing `lockstep` (read with a `None` appended).
#[derive(Serialize, Deserialize)]
struct SidecarV3 {
    sequence: u64,
    unix_ms: u64,
    counters: ServiceCounters,
    rejected: BTreeMap<String, u64>,
    limiter_config: LimiterConfig,
    limiter: LimiterCounters,
    seed: u64,
    streams: StreamsV3,
    lockstep: Option<crate::lockstep::Saved>,
}

impl From<SidecarV3> for Sidecar {
    fn from(v3: SidecarV3) -> Self {
        let SidecarV3 {
            sequence,
            unix_ms,
            counters,
            rejected,
            limiter_config,
            limiter,
            seed,
            streams,
            lockstep,
        } = v3;
        Sidecar {
            sequence,
            unix_ms,
            counters,
            rejected,
            limiter_config,
            limiter,
            seed,
            streams: streams.into(),
            lockstep,
        }
    }
}

impl Sidecar {
    /// What this snapshot makes durable, once it is.
    pub fn durable_marks(&self) -> proto::DurableMarks {
        proto::DurableMarks { snapshot_sequence: self.sequence, marks: self.streams.marks() }
    }
}

/// Why a snapshot could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotFileError {
    /// Reading or writing failed.
    #[error("snapshot i/o: {0}")]
    Io(#[from] io::Error),
    /// The file is not a replay-server snapshot.
    #[error("not a replay-server snapshot (bad magic)")]
    BadMagic,
    /// Written by a format version this build does not read.
    #[error("replay-server snapshot version {found} is not supported (this build reads {supported})")]
    UnsupportedVersion {
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        supported: u32,
    },
    /// The sidecar is corrupt (checksum, size or contents).
    #[error("replay-server snapshot sidecar is corrupt: {0}")]
    Sidecar(String),
    /// The buffer part was rejected by `replay`.
    #[error(transparent)]
    Buffer(#[from] replay::SnapshotError),
    /// The write was abandoned because the replica fell too far behind while writing.
    #[error("snapshot write abandoned: the replica's log exceeded its budget")]
    Aborted,
}

/// Writes one snapshot (sidecar, then buffer) to `w`.
pub fn write_to<W: Write>(
    w: &mut W,
    buffer: &ReplayBuffer,
    sidecar: &Sidecar,
) -> Result<(), SnapshotFileError> {
    let encoded = bincode::serde::encode_to_vec(sidecar, bincode::config::standard())
        .map_err(|e| SnapshotFileError::Sidecar(e.to_string()))?;
    let len = u32::try_from(encoded.len()).map_err(|_| SnapshotFileError::Sidecar("too large".into()))?;
    w.write_all(&SERVER_SNAPSHOT_MAGIC)?;
    w.write_all(&SERVER_SNAPSHOT_VERSION.to_le_bytes())?;
    w.write_all(&len.to_le_bytes())?;
    w.write_all(&crc32fast::hash(&encoded).to_le_bytes())?;
    w.write_all(&encoded)?;
    buffer.write_snapshot(w)?;
    Ok(())
}

/// Reads a snapshot written by [`write_to`] for `cfg` and `dims`.
pub fn read_from<R: Read>(
    r: &mut R,
    cfg: ReplayConfig,
    dims: Dims,
) -> Result<(ReplayBuffer, Sidecar), SnapshotFileError> {
    let mut header = [0u8; 20];
    r.read_exact(&mut header)?;
    if header[..8] != SERVER_SNAPSHOT_MAGIC {
        return Err(SnapshotFileError::BadMagic);
    }
    let word = |at: usize| u32::from_le_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]]);
    let version = word(8);
    if !(2..=SERVER_SNAPSHOT_VERSION).contains(&version) {
        return Err(SnapshotFileError::UnsupportedVersion {
            found: version,
            supported: SERVER_SNAPSHOT_VERSION,
        });
    }
    let (len, crc) = (word(12), word(16));
    if len > MAX_SIDECAR_BYTES {
        return Err(SnapshotFileError::Sidecar(format!("declared length {len} is implausible")));
    }
    let mut encoded = vec![0u8; len as usize];
    r.read_exact(&mut encoded)?;
    if crc32fast::hash(&encoded) != crc {
        return Err(SnapshotFileError::Sidecar("checksum mismatch".into()));
    }
    let decoded = match version {
        2 | 3 => {
            if version == 2 {
                encoded.push(0); // lockstep: None
            }
            bincode::serde::decode_from_slice::<SidecarV3, _>(&encoded, bincode::config::standard())
                .map(|(v3, used)| (Sidecar::from(v3), used))
        }
        _ => bincode::serde::decode_from_slice(&encoded, bincode::config::standard()),
    };
    let (sidecar, used) = decoded.map_err(|e| SnapshotFileError::Sidecar(e.to_string()))?;
    if used != encoded.len() {
        return Err(SnapshotFileError::Sidecar("trailing bytes".into()));
    }
    let buffer = ReplayBuffer::read_snapshot(r, cfg, dims)?;
    Ok((buffer, sidecar))
}

/// Reads the snapshot at `path`; `Ok(None)` when there is no file (a first start).
pub fn read_file(
    path: &Path,
    cfg: ReplayConfig,
    dims: Dims,
) -> Result<Option<(ReplayBuffer, Sidecar)>, SnapshotFileError> {
    let file = match File::open(path) {
        Ok(file) => file,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e.into()),
    };
    read_from(&mut BufReader::with_capacity(1 << 20, file), cfg, dims).map(Some)
}

/// A writer that fails once `abort` is set, so a long serialisation can be abandoned between writes.
struct Abortable<'a, W> {
    inner: W,
    abort: &'a AtomicBool,
}

impl<W: Write> Write for Abortable<'_, W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.abort.load(Ordering::Relaxed) {
            return Err(io::Error::other("snapshot aborted"));
        }
        self.inner.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// How long the parts of one write took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WriteTimes {
    /// Producing the bytes (the buffer is needed only for this part).
    pub serialise: Duration,
    /// Bytes written.
    pub bytes: u64,
}

/// Writes snapshots to one path, atomically; durability (fsync, rename) runs on a helper thread.
#[derive(Debug)]
pub struct FileWriter {
    path: PathBuf,
    syncing: Option<JoinHandle<io::Result<()>>>,
}

impl FileWriter {
    /// A writer for `path`.
    pub fn new(path: PathBuf) -> Self {
        Self { path, syncing: None }
    }

    /// Serialises a snapshot to `<path>.tmp`, then leaves fsync and rename to a helper thread,
    /// which calls `on_durable` with the outcome. Waits first for the previous snapshot's helper
    /// (one temporary file at a time).
    pub fn write(
        &mut self,
        buffer: &ReplayBuffer,
        sidecar: &Sidecar,
        abort: &AtomicBool,
        on_durable: impl FnOnce(&io::Result<()>) + Send + 'static,
    ) -> Result<WriteTimes, SnapshotFileError> {
        self.finish()?;
        let started = Instant::now();
        let produced = (|| {
            let tmp = durable::temporary_beside(&self.path)?;
            let mut w = BufWriter::with_capacity(1 << 20, Abortable { inner: tmp, abort });
            write_to(&mut w, buffer, sidecar)?;
            let tmp = w.into_inner().map_err(|e| e.into_error())?.inner;
            let bytes = tmp.as_file().metadata()?.len();
            Ok::<_, SnapshotFileError>((tmp, bytes))
        })();
        // On failure the temporary file is dropped, which removes it.
        let (tmp, bytes) = produced
            .map_err(|e| if abort.load(Ordering::Relaxed) { SnapshotFileError::Aborted } else { e })?;
        let serialise = started.elapsed();
        let path = self.path.clone();
        self.syncing =
            Some(std::thread::Builder::new().name("replay-snapshot-sync".into()).spawn(move || {
                let published = durable::publish(tmp, &path);
                on_durable(&published);
                published
            })?);
        Ok(WriteTimes { serialise, bytes })
    }

    /// Waits until the last snapshot is durable under its final name.
    pub fn finish(&mut self) -> Result<(), SnapshotFileError> {
        if let Some(handle) = self.syncing.take() {
            handle.join().map_err(|_| io::Error::other("snapshot sync thread panicked"))??;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::fs;

    use super::*;
    use replay::TransitionBatch;

    const DIMS: Dims = Dims { obs_dim: 2, act_dim: 1 };

    fn cfg() -> ReplayConfig {
        ReplayConfig { capacity_transitions: 8, ..ReplayConfig::default() }
    }

    fn filled() -> ReplayBuffer {
        let mut buffer = ReplayBuffer::new(cfg(), DIMS).unwrap();
        buffer
            .insert_batch(TransitionBatch {
                observations: &[0.0, 1.0, 2.0, 3.0],
                actions: &[0.5, -0.5],
                rewards: &[1.0, 2.0],
                next_observations: &[2.0, 3.0, 4.0, 5.0],
                terminated: &[false, true],
                abs_td_errors: Some(&[0.25, 4.0]),
            })
            .unwrap();
        buffer
    }

    fn sidecar() -> Sidecar {
        let mut counters = ServiceCounters { inserted_transitions: 2, ..ServiceCounters::default() };
        counters.refused.insert("below_min_size".into(), 3);
        Sidecar {
            sequence: 7,
            unix_ms: 1,
            counters,
            rejected: BTreeMap::from([("experience/checksum".to_string(), 5)]),
            limiter_config: LimiterConfig {
                min_size_to_sample: 1,
                samples_per_insert: Some(2.0),
                tolerance: 4.0,
            },
            limiter: LimiterCounters { inserted: 2, sampled: 0, uncredited: 1 },
            seed: 9,
            streams: {
                let mut streams = Streams::default();
                streams.record(3, 77, 0);
                streams
            },
            lockstep: None,
        }
    }

    /// `sidecar` as format `version` (2 or 3) wrote it: without refused batches, and in version 2
    /// without the trailing `lockstep` (bincode writes None as one 0 byte).
    fn old_format(sidecar: Sidecar, version: u32) -> Vec<u8> {
        let Sidecar {
            sequence,
            unix_ms,
            counters,
            rejected,
            limiter_config,
            limiter,
            seed,
            streams,
            lockstep,
        } = sidecar;
        let v3 = SidecarV3 {
            sequence,
            unix_ms,
            counters,
            rejected,
            limiter_config,
            limiter,
            seed,
            streams: streams.into(),
            lockstep,
        };
        let mut encoded = bincode::serde::encode_to_vec(v3, bincode::config::standard()).unwrap();
        if version == 2 {
            assert_eq!(encoded.pop(), Some(0));
        }
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&SERVER_SNAPSHOT_MAGIC);
        bytes.extend_from_slice(&version.to_le_bytes());
        bytes.extend_from_slice(&(encoded.len() as u32).to_le_bytes());
        bytes.extend_from_slice(&crc32fast::hash(&encoded).to_le_bytes());
        bytes.extend_from_slice(&encoded);
        filled().write_snapshot(&mut bytes).unwrap();
        bytes
    }

    #[test]
    fn version_2_and_3_snapshots_are_read_and_a_cut_round_trips() {
        for version in [2, 3] {
            let (_, side) = read_from(&mut &old_format(sidecar(), version)[..], cfg(), DIMS).unwrap();
            assert_eq!(side, sidecar(), "version {version}");
        }
        // Refused batches are saved since version 4; older files read them as stored.
        let mut refusing = sidecar();
        refusing.streams.decide(3, 77, 1, true);
        let mut bytes = Vec::new();
        write_to(&mut bytes, &filled(), &refusing).unwrap();
        assert!(read_from(&mut &bytes[..], cfg(), DIMS).unwrap().1.streams.refused(3, 77, 1));
        let (_, side) = read_from(&mut &old_format(refusing, 3)[..], cfg(), DIMS).unwrap();
        assert!(side.streams.seen(3, 77, 1) && !side.streams.refused(3, 77, 1));
        // A deterministic cut travels with the sidecar.
        let saved = crate::lockstep::Saved {
            cut: 500,
            progress: vec![1250, 1250],
            staged: BTreeMap::new(),
            inserted_blocks: 20,
            queued: vec![],
            applied_through: 492,
            served: Some(496),
        };
        let with_cut = Sidecar { lockstep: Some(saved), ..sidecar() };
        let mut bytes = Vec::new();
        write_to(&mut bytes, &filled(), &with_cut).unwrap();
        assert_eq!(read_from(&mut &bytes[..], cfg(), DIMS).unwrap().1, with_cut);
    }

    #[test]
    fn round_trip_and_corruption() {
        let mut bytes = Vec::new();
        write_to(&mut bytes, &filled(), &sidecar()).unwrap();
        let (buffer, side) = read_from(&mut &bytes[..], cfg(), DIMS).unwrap();
        assert_eq!(side, sidecar());
        assert_eq!(buffer.counters(), filled().counters());
        let mut bad = bytes.clone();
        bad[0] = b'X';
        assert!(matches!(read_from(&mut &bad[..], cfg(), DIMS), Err(SnapshotFileError::BadMagic)));
        let mut bad = bytes.clone();
        bad[8] = 1; // the format before streams were saved
        assert!(matches!(
            read_from(&mut &bad[..], cfg(), DIMS),
            Err(SnapshotFileError::UnsupportedVersion { .. })
        ));
        let mut bad = bytes.clone();
        bad[21] ^= 1;
        assert!(matches!(read_from(&mut &bad[..], cfg(), DIMS), Err(SnapshotFileError::Sidecar(_))));
        let mut bad = bytes.clone();
        let last = bad.len() - 20;
        bad[last] ^= 1;
        assert!(matches!(read_from(&mut &bad[..], cfg(), DIMS), Err(SnapshotFileError::Buffer(_))));
        let short = &bytes[..bytes.len() - 1];
        assert!(read_from(&mut &short[..], cfg(), DIMS).is_err());
    }

    #[test]
    fn file_writer_publishes_atomically_and_can_abort() {
        let dir = std::env::temp_dir().join(format!("replay-server-snapshot-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("replay.snap");
        assert!(read_file(&path, cfg(), DIMS).unwrap().is_none(), "no file is a first start");
        let mut writer = FileWriter::new(path.clone());
        let abort = AtomicBool::new(false);
        let times = writer.write(&filled(), &sidecar(), &abort, |r| assert!(r.is_ok())).unwrap();
        writer.finish().unwrap();
        assert_eq!(times.bytes, fs::metadata(&path).unwrap().len());
        let (_, side) = read_file(&path, cfg(), DIMS).unwrap().unwrap();
        assert_eq!(side.sequence, 7);
        abort.store(true, Ordering::Relaxed);
        let newer = Sidecar { sequence: 8, ..sidecar() };
        assert!(matches!(
            writer.write(&filled(), &newer, &abort, |_| panic!("aborted writes publish nothing")),
            Err(SnapshotFileError::Aborted)
        ));
        let (_, side) = read_file(&path, cfg(), DIMS).unwrap().unwrap();
        assert_eq!(side.sequence, 7, "an aborted write leaves the previous snapshot");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1, "and no temporary file");
        fs::remove_dir_all(&dir).unwrap();
    }
}
