//! The snapshot replica: a second buffer on its own thread that replays every mutation of the
//! service in order, and writes snapshots from its own copy.
//!
//! Why: a consistent snapshot of a 1M-transition Ant buffer is ~0.5 GB. Writing it under the
//! service's lock stops inserts and sampling for seconds (Reverb's behaviour); cloning it under the
//! lock still costs a ~0.5 GB copy plus page faults (hundreds of ms). The replica is identical to
//! the service's buffer after the same operations (every operation is deterministic), so a
//! snapshot request is just one more message in the operation log: the service pays the enqueueing
//! of one small message, the replica pauses its replay while it serialises (the log grows
//! meanwhile) and catches up afterwards. The cost is a second copy of the buffer in memory and a
//! second application of every insert, on another thread.
//!
//! The log is bounded in bytes (`snapshot_log_budget_bytes`): if it outgrows the budget while a
//! snapshot is being serialised, the write is abandoned (counted, retried at the next interval);
//! outside writes the server briefly holds back inserts until the replica has caught up.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;

use proto::{ExperienceBatch, PriorityUpdate};
use rand::SeedableRng;
use rand::rngs::StdRng;
use replay::ReplayBuffer;

use crate::config::InitialPriority;
use crate::service::insert_experience;
use crate::snapshot::{FileWriter, Sidecar, SnapshotFileError};

/// One mutation of the service's buffer, or a snapshot request, in log order.
#[derive(Debug)]
pub enum Op {
    /// `insert_experience(batch, rule)`.
    Insert {
        /// The batch as inserted.
        batch: ExperienceBatch,
        /// The priority rule it was inserted under.
        rule: InitialPriority,
    },
    /// `update_priorities` with these fields.
    Update(PriorityUpdate),
    /// A sample was served (only the buffer's sample counter changes; the replica samples too).
    Sampled {
        /// Its batch size.
        batch_size: u32,
        /// Its learner step.
        learner_step: u64,
    },
    /// Write a snapshot of the state reached at this point of the log, with this sidecar.
    Snapshot(Box<Sidecar>),
    /// No operation: wakes a stopping replica so that it sees its stop flag.
    Wake,
}

impl Op {
    /// Bytes this operation holds while queued (what the log budget counts).
    fn bytes(&self) -> u64 {
        match self {
            Op::Insert { batch, .. } => {
                let t = &batch.transitions;
                let floats = t.observations.len()
                    + t.next_observations.len()
                    + t.actions.len()
                    + t.rewards.len()
                    + batch.td_errors.len();
                (4 * floats + t.terminated.len()) as u64
            }
            Op::Update(update) => (20 * update.slots.len()) as u64,
            Op::Sampled { .. } | Op::Snapshot(_) | Op::Wake => 64,
        }
    }
}

/// What the replica has written, for stats and the report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SnapshotLog {
    /// Snapshots durable under their final name (fsynced and renamed).
    pub written: u64,
    /// Snapshots that failed (I/O, serialising or publishing).
    pub failed: u64,
    /// Snapshots abandoned because the log outgrew its budget.
    pub aborted: u64,
    /// Sequence number of the last durable one.
    pub last_sequence: u64,
    /// Serialisation time of the last one, ms.
    pub last_serialise_ms: f64,
    /// Size of the last one, bytes.
    pub last_bytes: u64,
    /// The last error, if the last attempt failed.
    pub last_error: Option<String>,
    /// What the last durable snapshot made durable.
    pub durable: Option<proto::DurableMarks>,
}

/// State shared between the service side and the replica thread.
#[derive(Debug, Default)]
struct Shared {
    lag_bytes: AtomicU64,
    writing: AtomicBool,
    abort: AtomicBool,
    stop: AtomicBool,
    log: Mutex<SnapshotLog>,
}

/// The service's end: sends operations and reads the replica's state.
#[derive(Debug, Clone)]
pub struct ReplicaLink {
    tx: Sender<Op>,
    shared: Arc<Shared>,
    budget_bytes: u64,
}

impl ReplicaLink {
    /// Appends `op` to the log. If the log outgrows its budget during a write, abandons the write.
    pub fn send(&self, op: Op) {
        let bytes = op.bytes();
        let lag = self.shared.lag_bytes.fetch_add(bytes, Ordering::Relaxed) + bytes;
        if lag > self.budget_bytes && self.shared.writing.load(Ordering::Relaxed) {
            self.shared.abort.store(true, Ordering::Relaxed);
        }
        if self.tx.send(op).is_err() {
            // The replica is gone (stopped or panicked); the log must not count what nobody drains.
            self.shared.lag_bytes.fetch_sub(bytes, Ordering::Relaxed);
        }
    }

    /// Bytes queued and not yet applied.
    pub fn lag_bytes(&self) -> u64 {
        self.shared.lag_bytes.load(Ordering::Relaxed)
    }

    /// True when the log is over budget outside a write: inserts should wait for the replica.
    pub fn needs_backpressure(&self) -> bool {
        self.lag_bytes() > self.budget_bytes && !self.shared.writing.load(Ordering::Relaxed)
    }

    /// Whether a snapshot is being serialised now.
    pub fn writing(&self) -> bool {
        self.shared.writing.load(Ordering::Relaxed)
    }

    /// What has been written so far.
    pub fn log(&self) -> SnapshotLog {
        self.shared.log.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// The replica thread and its link.
#[derive(Debug)]
pub struct Replica {
    link: ReplicaLink,
    thread: JoinHandle<()>,
}

impl Replica {
    /// Starts a replica of `buffer` (which must equal the service's buffer) writing to `writer`.
    pub fn start(buffer: ReplayBuffer, writer: FileWriter, budget_bytes: u64) -> std::io::Result<Self> {
        let (tx, rx) = mpsc::channel();
        let shared = Arc::new(Shared::default());
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("replay-replica".into())
            .spawn(move || run(buffer, rx, thread_shared, writer))?;
        Ok(Self { link: ReplicaLink { tx, shared, budget_bytes }, thread })
    }

    /// A link to hand to the service.
    pub fn link(&self) -> ReplicaLink {
        self.link.clone()
    }

    /// Stops the replica without applying what is still queued (the final snapshot is written from
    /// the service's buffer), abandoning a write in progress; waits for it and for the last fsync.
    pub fn stop(self) -> SnapshotLog {
        self.link.shared.stop.store(true, Ordering::Relaxed);
        self.link.shared.abort.store(true, Ordering::Relaxed);
        self.link.send(Op::Wake);
        let Replica { link, thread } = self;
        let shared = Arc::clone(&link.shared);
        drop(link);
        if thread.join().is_err() {
            tracing::error!("snapshot replica panicked");
        }
        shared.log.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

fn run(mut buffer: ReplayBuffer, rx: Receiver<Op>, shared: Arc<Shared>, mut writer: FileWriter) {
    // The replica's samples only advance its sample counter; which transitions it draws is irrelevant.
    let mut rng = StdRng::seed_from_u64(0);
    let mut scratch = replay::SampledBatch::new();
    while let Ok(op) = rx.recv() {
        if shared.stop.load(Ordering::Relaxed) {
            break;
        }
        let bytes = op.bytes();
        let applied = match &op {
            Op::Insert { batch, rule } => insert_experience(&mut buffer, batch, *rule).map(drop),
            Op::Update(u) => buffer.update_priorities(&u.slots, &u.generations, &u.td_errors).map(drop),
            Op::Sampled { batch_size, learner_step } => {
                buffer.sample(*batch_size as usize, *learner_step, &mut rng, &mut scratch)
            }
            Op::Snapshot(sidecar) => {
                write(&buffer, sidecar, &shared, &mut writer);
                Ok(())
            }
            Op::Wake => Ok(()),
        };
        if let Err(e) = applied {
            // The service applied the same call successfully on an identical buffer: a bug.
            tracing::error!(error = %e, "snapshot replica diverged from the buffer; snapshots stop");
            shared.log.lock().unwrap_or_else(PoisonError::into_inner).last_error = Some(e.to_string());
            break;
        }
        shared.lag_bytes.fetch_sub(bytes, Ordering::Relaxed);
    }
    // A failure here was already booked by the durability callback.
    let _ = writer.finish();
}

fn write(buffer: &ReplayBuffer, sidecar: &Sidecar, shared: &Arc<Shared>, writer: &mut FileWriter) {
    shared.abort.store(false, Ordering::Relaxed);
    shared.writing.store(true, Ordering::Relaxed);
    let sequence = sidecar.sequence;
    let marks = sidecar.durable_marks();
    let on_durable = {
        let shared = Arc::clone(shared);
        move |published: &std::io::Result<()>| {
            let mut log = shared.log.lock().unwrap_or_else(PoisonError::into_inner);
            match published {
                Ok(()) => {
                    log.written += 1;
                    log.last_sequence = sequence;
                    log.last_error = None;
                    log.durable = Some(marks);
                }
                Err(e) => {
                    log.failed += 1;
                    log.last_error = Some(e.to_string());
                    tracing::error!(sequence, error = %e, "snapshot did not become durable");
                }
            }
        }
    };
    let result = writer.write(buffer, sidecar, &shared.abort, on_durable);
    shared.writing.store(false, Ordering::Relaxed);
    let mut log = shared.log.lock().unwrap_or_else(PoisonError::into_inner);
    match result {
        Ok(times) => {
            log.last_serialise_ms = times.serialise.as_secs_f64() * 1e3;
            log.last_bytes = times.bytes;
            tracing::info!(
                sequence,
                bytes = times.bytes,
                serialise_ms = log.last_serialise_ms,
                "snapshot serialised"
            );
        }
        Err(SnapshotFileError::Aborted) => {
            log.aborted += 1;
            log.last_error = Some(SnapshotFileError::Aborted.to_string());
            tracing::warn!(sequence = sidecar.sequence, "snapshot abandoned: replica log over budget");
        }
        Err(e) => {
            log.failed += 1;
            log.last_error = Some(e.to_string());
            tracing::error!(sequence = sidecar.sequence, error = %e, "snapshot failed");
        }
    }
}
