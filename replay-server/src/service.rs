//! The replay service, sans-IO: the buffer, the rate limiter, counters and rejections, driven by
//! message bytes (or already decoded messages) and answering with typed outcomes. The zenoh shell
//! in `server` moves bytes in and out; tests drive this directly.
//!
//! Every mutation of the buffer is also sent, in the same order, to the snapshot replica when one
//! is attached (see `replica`), which is what lets snapshots be written without pausing this.

use std::collections::BTreeMap;
use std::time::Instant;

use proto::{DecodeError, ExperienceBatch, PriorityUpdate, RefusalReason, SampleRequest, SampledBatch};
use rand::SeedableRng;
use rand::rngs::StdRng;
use replay::{InsertOutcome, ReplayBuffer, ReplayError, TransitionBatch, UpdateOutcome};
use serde::{Deserialize, Serialize};

use crate::config::{InitialPriority, ReplayServerConfig};
use crate::limiter::{Blocked, RateLimiter, Resumed};
use crate::lockstep::{Lockstep, Plan};
use crate::rejects::{Input, Rejection, Rejects};
use crate::replica::{Op, ReplicaLink};
use crate::snapshot::Sidecar;
use crate::streams::Streams;

/// What the server has done since its first start (restored with snapshots).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ServiceCounters {
    /// Experience messages inserted.
    pub insert_messages: u64,
    /// Transitions inserted.
    pub inserted_transitions: u64,
    /// Batches served.
    pub sampled_batches: u64,
    /// Transitions served.
    pub sampled_transitions: u64,
    /// Priority-update messages applied.
    pub priority_messages: u64,
    /// Priority updates written to live transitions.
    pub priorities_applied: u64,
    /// Priority updates ignored because their transition had been overwritten.
    pub priorities_stale: u64,
    /// Sample requests refused, by reason (`below_min_size`, `rate_limited`, `batch_too_large`, ...).
    pub refused: BTreeMap<String, u64>,
    /// Milliseconds sample requests spent blocked, by reason.
    pub blocked_ms: BTreeMap<String, u64>,
    /// Re-sent experience batches recognised and not stored again (their stream had them decided).
    pub duplicate_batches: u64,
    /// Transitions in those.
    pub duplicate_transitions: u64,
}

/// What blocked sample requests are waiting for right now (for the stats topic).
#[derive(Debug, Clone, PartialEq)]
pub struct Waiting {
    /// Requests waiting.
    pub count: usize,
    /// Arrival of the oldest, Unix milliseconds.
    pub since_unix_ms: u64,
    /// Why the oldest waits, in words.
    pub why: String,
}

/// The answer to a sample request.
#[derive(Debug, Clone, PartialEq)]
pub enum SampleOutcome {
    /// Served.
    Batch(SampledBatch),
    /// Refused now; waiting would not help.
    Refused(RefusalReason),
    /// The limiter says wait: hold the request until inserts lift the block or its deadline passes.
    Blocked(Blocked),
}

/// Settings the service checks messages against.
#[derive(Debug, Clone)]
struct Limits {
    obs_dim: u32,
    act_dim: u32,
    max_batch_size: u32,
    max_insert_transitions: u32,
    max_experience_bytes: u64,
    initial_priority: InitialPriority,
    seed: u64,
}

/// The buffer and everything around it that the server's handlers share.
#[derive(Debug)]
pub struct Service {
    buffer: ReplayBuffer,
    limiter: RateLimiter,
    counters: ServiceCounters,
    rejects: Rejects,
    limits: Limits,
    replica: Option<ReplicaLink>,
    /// Decided batches per executor stream (dedupe of re-sends; saved with snapshots).
    streams: Streams,
    sequence: u64,
    waiting: Option<Waiting>,
    insert_wait: Option<Waiting>,
    scratch: replay::SampledBatch,
    /// Deterministic mode's staging; `None` in normal mode.
    lockstep: Option<Lockstep>,
}

/// Inserts an experience batch into `buffer` under `rule`; shared by the service and its replica,
/// which must make identical calls to stay identical.
pub(crate) fn insert_experience(
    buffer: &mut ReplayBuffer,
    batch: &ExperienceBatch,
    rule: InitialPriority,
) -> Result<InsertOutcome, ReplayError> {
    let t = &batch.transitions;
    buffer.insert_batch(TransitionBatch {
        observations: &t.observations,
        actions: &t.actions,
        rewards: &t.rewards,
        next_observations: &t.next_observations,
        terminated: &t.terminated,
        abs_td_errors: match rule {
            InitialPriority::TdError => Some(&batch.td_errors),
            InitialPriority::Max => None,
        },
    })
}

/// The generator for batch number `index`: a pure function of (seed, index), so a restored server
/// continues the sample sequence without saving generator state.
fn batch_rng(seed: u64, index: u64) -> StdRng {
    StdRng::seed_from_u64(splitmix64(seed ^ splitmix64(index)))
}

fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Service {
    /// A service over `buffer` (new, or restored with its `sidecar`), for a validated `cfg`.
    pub fn new(cfg: &ReplayServerConfig, buffer: ReplayBuffer, sidecar: Option<Sidecar>) -> (Self, Resumed) {
        let size = buffer.len() as u64;
        let saved = sidecar.as_ref().map(|s| (s.limiter_config, s.limiter));
        let lockstep = match (cfg.lockstep, sidecar.as_ref().and_then(|s| s.lockstep.clone())) {
            (Some(schedule), Some(saved)) => Some(Lockstep::restore(schedule, saved)),
            (Some(schedule), None) if cfg.snapshots_enabled() && schedule.checkpoint_every_updates > 0 => {
                Some(Lockstep::new(schedule).with_cuts())
            }
            (schedule, _) => schedule.map(Lockstep::new),
        };
        let (limiter, resumed) = RateLimiter::resume(cfg.limiter(), saved, size);
        let (counters, rejects, streams, sequence) = match sidecar {
            Some(s) => (s.counters, Rejects::from_counts(s.rejected), s.streams, s.sequence),
            None => (ServiceCounters::default(), Rejects::default(), Streams::default(), 0),
        };
        let limits = Limits {
            obs_dim: cfg.obs_dim,
            act_dim: cfg.act_dim,
            max_batch_size: cfg.max_batch_size,
            max_insert_transitions: cfg.max_insert_transitions,
            max_experience_bytes: cfg.max_experience_bytes(),
            initial_priority: cfg.initial_priority,
            seed: cfg.seed,
        };
        let service = Self {
            buffer,
            limiter,
            counters,
            rejects,
            limits,
            replica: None,
            streams,
            sequence,
            waiting: None,
            insert_wait: None,
            scratch: replay::SampledBatch::new(),
            lockstep,
        };
        (service, resumed)
    }

    /// Sends every later mutation to `link` as well.
    pub fn attach_replica(&mut self, link: ReplicaLink) {
        self.replica = Some(link);
    }

    /// Stops sending mutations to the replica and hands its link back (dropping it ends the replica).
    pub fn detach_replica(&mut self) -> Option<ReplicaLink> {
        self.replica.take()
    }

    /// The replica link, if snapshots are on.
    pub fn replica(&self) -> Option<&ReplicaLink> {
        self.replica.as_ref()
    }

    /// The buffer.
    pub fn buffer(&self) -> &ReplayBuffer {
        &self.buffer
    }

    /// The rate limiter.
    pub fn limiter(&self) -> &RateLimiter {
        &self.limiter
    }

    /// Counters since the first start.
    pub fn counters(&self) -> &ServiceCounters {
        &self.counters
    }

    /// Rejections by reason.
    pub fn rejects(&self) -> &Rejects {
        &self.rejects
    }

    /// Decided batches per executor stream.
    pub fn streams(&self) -> &Streams {
        &self.streams
    }

    /// Number of the last snapshot requested (or restored).
    pub fn snapshot_sequence(&self) -> u64 {
        self.sequence
    }

    /// Counts and logs a rejection.
    pub fn reject(&mut self, rejection: &Rejection, now: Instant) {
        self.rejects.record(&rejection.key(), &rejection.detail, now);
    }

    /// Refuses an experience payload too large to be one of ours, before spending time decoding it.
    pub fn check_experience_size(&mut self, len: usize, now: Instant) -> Result<(), Rejection> {
        if len as u64 <= self.limits.max_experience_bytes {
            return Ok(());
        }
        let detail =
            format!("{len} bytes, more than {} (max_insert_transitions)", self.limits.max_experience_bytes);
        Err(self.rejected(Rejection { input: Input::Experience, reason: "too_large", detail }, now))
    }

    /// Decodes and inserts an experience payload; returns the transitions inserted.
    pub fn handle_experience(&mut self, payload: &[u8], now: Instant) -> Result<u64, Rejection> {
        self.check_experience_size(payload.len(), now)?;
        self.accept_experience(proto::decode(payload), now)
    }

    /// Inserts a decoded experience batch (decoding happens outside the lock in the server). A batch
    /// of a stream (nonzero `stream`) is decided once: stored or refused, and recorded either way,
    /// so that a re-send of it is recognised (counted as a duplicate, `Ok(0)`) and not stored twice.
    pub fn accept_experience(
        &mut self,
        decoded: Result<ExperienceBatch, DecodeError>,
        now: Instant,
    ) -> Result<u64, Rejection> {
        let batch = decoded.map_err(|e| self.rejected(Rejection::decode(Input::Experience, &e), now))?;
        let (executor, stream, seq) = (batch.executor_id, batch.stream, batch.seq);
        if stream == 0 {
            return self.insert_checked(batch, now);
        }
        if self.streams.seen(executor, stream, seq) {
            self.counters.duplicate_batches += 1;
            self.counters.duplicate_transitions += batch.len() as u64;
            return Ok(0);
        }
        let decided = self.insert_checked(batch, now);
        self.streams.decide(executor, stream, seq, decided.is_err());
        decided
    }

    /// Deterministic mode's state (its last cut, each executor's env steps delivered, whether it
    /// cuts); `None` in normal mode.
    pub fn lockstep(&self) -> Option<&Lockstep> {
        self.lockstep.as_ref()
    }

    /// Deterministic mode: snapshots the state at the next checkpoint step once it is complete.
    fn cut_if_due(&mut self) {
        let Some(lockstep) = self.lockstep.as_mut() else { return };
        let Some(at) = lockstep.cut_due() else { return };
        let saved = lockstep.cut(at);
        let mut sidecar = self.next_sidecar(node::unix_ms());
        sidecar.lockstep = Some(saved);
        tracing::info!(
            learner_step = at,
            sequence = sidecar.sequence,
            "deterministic mode: state cut, snapshot requested"
        );
        if let Some(replica) = &self.replica {
            replica.send(Op::Snapshot(Box::new(sidecar)));
        }
    }

    /// Checks a decoded batch against the task and limits and inserts it, or in deterministic mode
    /// stages it until its round.
    fn insert_checked(&mut self, batch: ExperienceBatch, now: Instant) -> Result<u64, Rejection> {
        self.check_batch(&batch, now)?;
        let Some(lockstep) = self.lockstep.as_mut() else { return self.insert(batch) };
        let n = batch.len() as u64;
        match lockstep.stage(batch) {
            Ok(()) => {
                self.cut_if_due();
                Ok(n)
            }
            Err((reason, detail)) => {
                Err(self.rejected(Rejection { input: Input::Experience, reason, detail }, now))
            }
        }
    }

    /// Checks a decoded batch against the task and limits.
    fn check_batch(&mut self, batch: &ExperienceBatch, now: Instant) -> Result<(), Rejection> {
        let t = &batch.transitions;
        if (t.obs_dim, t.act_dim) != (self.limits.obs_dim, self.limits.act_dim) {
            let detail = format!(
                "obs_dim {} act_dim {} from executor {}, the server's task has {} and {}",
                t.obs_dim, t.act_dim, batch.executor_id, self.limits.obs_dim, self.limits.act_dim
            );
            return Err(self.rejected(Rejection { input: Input::Experience, reason: "dims", detail }, now));
        }
        if batch.len() > self.limits.max_insert_transitions as usize {
            let detail =
                format!("{} transitions, more than {}", batch.len(), self.limits.max_insert_transitions);
            return Err(
                self.rejected(Rejection { input: Input::Experience, reason: "too_large", detail }, now)
            );
        }
        Ok(())
    }

    /// Inserts a checked batch; returns the transitions inserted (none for a marker).
    fn insert(&mut self, batch: ExperienceBatch) -> Result<u64, Rejection> {
        if batch.is_empty() {
            return Ok(0);
        }
        if let Err(e) = insert_experience(&mut self.buffer, &batch, self.limits.initial_priority) {
            // Validation already covers what the buffer checks; this is a second line of defence.
            let detail = e.to_string();
            let rejection = Rejection { input: Input::Experience, reason: "buffer", detail };
            return Err(self.rejected(rejection, Instant::now()));
        }
        let n = batch.len() as u64;
        self.limiter.on_insert(n);
        self.counters.insert_messages += 1;
        self.counters.inserted_transitions += n;
        if let Some(replica) = &self.replica {
            replica.send(Op::Insert { batch, rule: self.limits.initial_priority });
        }
        Ok(n)
    }

    /// Decodes and applies a priority-update payload.
    pub fn handle_priorities(&mut self, payload: &[u8], now: Instant) -> Result<UpdateOutcome, Rejection> {
        self.accept_priorities(proto::decode(payload), now)
    }

    /// Applies a decoded priority update; updates of overwritten transitions count as stale.
    pub fn accept_priorities(
        &mut self,
        decoded: Result<PriorityUpdate, DecodeError>,
        now: Instant,
    ) -> Result<UpdateOutcome, Rejection> {
        let update = decoded.map_err(|e| self.rejected(Rejection::decode(Input::Priorities, &e), now))?;
        if let Some(lockstep) = self.lockstep.as_mut() {
            // Applied when the sample that must see it is served (`lockstep.rs`).
            lockstep.queue(update);
            self.cut_if_due();
            return Ok(UpdateOutcome::default());
        }
        self.apply_priorities(update, now)
    }

    /// Applies a priority update to the buffer.
    fn apply_priorities(&mut self, update: PriorityUpdate, now: Instant) -> Result<UpdateOutcome, Rejection> {
        let outcome =
            match self.buffer.update_priorities(&update.slots, &update.generations, &update.td_errors) {
                Ok(outcome) => outcome,
                Err(e) => {
                    let reason = match e {
                        ReplayError::SlotOutOfRange { .. } => "slot_range",
                        _ => "buffer",
                    };
                    let detail = e.to_string();
                    return Err(self.rejected(Rejection { input: Input::Priorities, reason, detail }, now));
                }
            };
        self.counters.priority_messages += 1;
        self.counters.priorities_applied += outcome.applied;
        self.counters.priorities_stale += outcome.stale;
        if let Some(replica) = &self.replica {
            replica.send(Op::Update(update));
        }
        Ok(outcome)
    }

    /// Decodes a sample request (a query without payload is malformed).
    pub fn decode_request(
        &mut self,
        payload: Option<&[u8]>,
        now: Instant,
    ) -> Result<SampleRequest, Rejection> {
        let decoded = match payload {
            Some(bytes) => proto::decode::<SampleRequest>(bytes),
            None => Err(DecodeError::TooShort { needed: proto::codec::HEADER_LEN, found: 0 }),
        };
        decoded.map_err(|e| self.rejected(Rejection::decode(Input::Sample, &e), now))
    }

    /// Serves `request` if the limiter (in deterministic mode, the schedule) allows it.
    pub fn try_sample(&mut self, request: &SampleRequest) -> SampleOutcome {
        if request.batch_size > self.limits.max_batch_size {
            let reason = RefusalReason::BatchTooLarge {
                requested: request.batch_size,
                max: self.limits.max_batch_size,
            };
            self.count_refusal("batch_too_large");
            return SampleOutcome::Refused(reason);
        }
        if self.lockstep.is_some() {
            return self.try_sample_lockstep(request);
        }
        if let Err(blocked) = self.limiter.check_sample(self.buffer.len() as u64, request.batch_size) {
            return SampleOutcome::Blocked(blocked);
        }
        self.sample(request)
    }

    /// Deterministic mode's sample: once the round's blocks and the previous request's priorities
    /// are in, applies those, inserts these in the canonical order, and samples.
    fn try_sample_lockstep(&mut self, request: &SampleRequest) -> SampleOutcome {
        self.cut_if_due();
        let Some(lockstep) = self.lockstep.as_mut() else { return self.sample(request) };
        let (priorities_through, blocks_through) = match lockstep.plan(request.learner_step) {
            Err(wait) => return SampleOutcome::Blocked(Blocked::Lockstep(wait)),
            Ok(Plan::Repeat(batch)) => {
                tracing::debug!(
                    learner_step = request.learner_step,
                    "deterministic mode: a repeated request"
                );
                return SampleOutcome::Batch(SampledBatch { request_id: request.request_id, ..batch });
            }
            Ok(Plan::Stale { served }) => {
                self.count_refusal("lockstep_stale");
                let detail = format!(
                    "deterministic mode: learner step {} was served before step {served}",
                    request.learner_step
                );
                return SampleOutcome::Refused(RefusalReason::Other { detail });
            }
            Ok(Plan::Sample { priorities_through, blocks_through }) => (priorities_through, blocks_through),
        };
        let (updates, batches) =
            (lockstep.take_priorities(priorities_through), lockstep.take_blocks(blocks_through));
        let now = Instant::now();
        for update in updates {
            // A bad update is counted inside and skipped, as in normal mode.
            let _ = self.apply_priorities(update, now);
        }
        for batch in batches {
            // Staged batches were checked; a buffer error is counted inside (a second line of defence).
            let _ = self.insert(batch);
        }
        let outcome = self.sample(request);
        if let (SampleOutcome::Batch(batch), Some(lockstep)) = (&outcome, self.lockstep.as_mut()) {
            lockstep.served(request.learner_step, batch);
        }
        outcome
    }

    /// Samples `request` from the buffer as it is.
    fn sample(&mut self, request: &SampleRequest) -> SampleOutcome {
        let mut rng = batch_rng(self.limits.seed, self.counters.sampled_batches);
        let batch_size = request.batch_size as usize;
        if let Err(e) = self.buffer.sample(batch_size, request.learner_step, &mut rng, &mut self.scratch) {
            // Unreachable while min_size_to_sample ≥ 1 and batch sizes ≥ 1 (both validated).
            self.count_refusal("other");
            return SampleOutcome::Refused(RefusalReason::Other { detail: e.to_string() });
        }
        let n = batch_size as u64;
        self.limiter.on_sample(n);
        self.counters.sampled_batches += 1;
        self.counters.sampled_transitions += n;
        if let Some(replica) = &self.replica {
            replica.send(Op::Sampled { batch_size: request.batch_size, learner_step: request.learner_step });
        }
        SampleOutcome::Batch(self.take_batch(request))
    }

    /// Moves the sampled columns into a wire batch (the scratch batch regrows on the next sample).
    fn take_batch(&mut self, request: &SampleRequest) -> SampledBatch {
        let s = &mut self.scratch;
        SampledBatch {
            request_id: request.request_id,
            learner_step: request.learner_step,
            slots: std::mem::take(&mut s.slots),
            generations: std::mem::take(&mut s.generations),
            is_weights: std::mem::take(&mut s.is_weights),
            transitions: proto::Transitions {
                obs_dim: self.limits.obs_dim,
                act_dim: self.limits.act_dim,
                observations: std::mem::take(&mut s.observations),
                actions: std::mem::take(&mut s.actions),
                rewards: std::mem::take(&mut s.rewards),
                next_observations: std::mem::take(&mut s.next_observations),
                terminated: std::mem::take(&mut s.terminated),
            },
        }
    }

    /// Counts a refused request under `key`.
    pub fn count_refusal(&mut self, key: &str) {
        *self.counters.refused.entry(key.to_string()).or_default() += 1;
    }

    /// Adds the time a request spent blocked for `key`.
    pub fn add_blocked_ms(&mut self, key: &str, ms: u64) {
        *self.counters.blocked_ms.entry(key.to_string()).or_default() += ms;
    }

    /// Records what blocked requests wait for now (`None`: nothing waits).
    pub fn set_waiting(&mut self, waiting: Option<Waiting>) {
        self.waiting = waiting;
    }

    /// What blocked requests wait for now.
    pub fn waiting(&self) -> Option<&Waiting> {
        self.waiting.as_ref()
    }

    /// Records that inserts are held back (for the replica to catch up), or no longer are.
    pub fn set_insert_wait(&mut self, wait: Option<Waiting>) {
        self.insert_wait = wait;
    }

    /// Why inserts are held back now, if they are.
    pub fn insert_wait(&self) -> Option<&Waiting> {
        self.insert_wait.as_ref()
    }

    /// Everything besides the buffer that a snapshot must carry, stamped with the next sequence number.
    pub fn next_sidecar(&mut self, unix_ms: u64) -> Sidecar {
        self.sequence += 1;
        Sidecar {
            sequence: self.sequence,
            unix_ms,
            counters: self.counters.clone(),
            rejected: self.rejects.counts().clone(),
            limiter_config: self.limiter.config(),
            limiter: self.limiter.counters(),
            seed: self.limits.seed,
            streams: self.streams.clone(),
            lockstep: None,
        }
    }

    /// Asks the replica to write a snapshot of the state as of now; false without a replica. Costs
    /// the service only the enqueueing of one small message.
    pub fn request_snapshot(&mut self, unix_ms: u64) -> bool {
        if self.replica.is_none() {
            return false;
        }
        let sidecar = self.next_sidecar(unix_ms);
        if let Some(replica) = &self.replica {
            replica.send(Op::Snapshot(Box::new(sidecar)));
        }
        true
    }

    fn rejected(&mut self, rejection: Rejection, now: Instant) -> Rejection {
        self.rejects.record(&rejection.key(), &rejection.detail, now);
        rejection
    }
}

#[cfg(test)]
mod tests;
