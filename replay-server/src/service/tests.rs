use std::path::PathBuf;
use std::time::{Duration, Instant};

use proto::{GlobalStep, MessageKind, Transitions};
use replay::{ReplayConfig, SlotRef};

use super::*;
use crate::replica::Replica;
use crate::snapshot::{self, FileWriter};

const OBS: u32 = 3;
const ACT: u32 = 2;

fn cfg() -> ReplayServerConfig {
    ReplayServerConfig {
        obs_dim: OBS,
        act_dim: ACT,
        buffer: ReplayConfig { capacity_transitions: 64, ..ReplayConfig::default() },
        min_size_to_sample: 8,
        max_batch_size: 16,
        max_insert_transitions: 32,
        seed: 7,
        ..ReplayServerConfig::default()
    }
}

fn service(cfg: &ReplayServerConfig) -> Service {
    let buffer = ReplayBuffer::new(cfg.buffer.clone(), cfg.dims()).unwrap();
    Service::new(cfg, buffer, None).0
}

/// `n` consecutive transitions whose values encode their global number `first + i`: observation
/// `[x, x, x]`, next observation `[x + 1; 3]`, action `[x, -x]`, reward `x`, TD error `x / 10`.
fn batch(first: u32, n: u32) -> ExperienceBatch {
    let mut t = Transitions::with_capacity(OBS, ACT, n as usize);
    for i in 0..n {
        let x = (first + i) as f32;
        let (obs, next) = ([x; 3], [x + 1.0; 3]);
        t.push(proto::Transition {
            observation: &obs,
            action: &[x, -x],
            reward: x,
            next_observation: &next,
            terminated: (first + i).is_multiple_of(5),
        })
        .unwrap();
    }
    let td_errors = (0..n).map(|i| (first + i) as f32 / 10.0).collect();
    ExperienceBatch {
        executor_id: 0,
        stream: 0,
        seq: 0,
        weights_version: 0,
        env_steps: 0,
        transitions: t,
        td_errors,
    }
}

fn request(id: u64, batch_size: u32) -> SampleRequest {
    SampleRequest { request_id: id, learner_step: 100, batch_size }
}

fn sample(service: &mut Service, batch_size: u32) -> SampledBatch {
    match service.try_sample(&request(1, batch_size)) {
        SampleOutcome::Batch(b) => b,
        other => panic!("expected a batch, got {other:?}"),
    }
}

/// Every sampled row is exactly one inserted transition (identified by its reward).
fn assert_rows_are_inserted_transitions(b: &SampledBatch) {
    let t = &b.transitions;
    for i in 0..b.len() {
        let row = t.get(i).unwrap();
        let x = row.reward;
        assert_eq!(row.observation, [x; 3]);
        assert_eq!(row.next_observation, [x + 1.0; 3]);
        assert_eq!(row.action, [x, -x]);
        assert_eq!(row.terminated, (x as u32).is_multiple_of(5));
    }
    assert!(b.is_weights.iter().all(|w| *w > 0.0 && *w <= 1.0));
    assert!(b.is_weights.contains(&1.0), "weights are normalised by the batch maximum");
}

#[test]
fn inserts_then_serves_exact_transitions() {
    let cfg = cfg();
    let mut s = service(&cfg);
    let now = Instant::now();
    assert_eq!(s.handle_experience(&proto::encode(&batch(1, 4)), now), Ok(4));
    assert!(matches!(
        s.try_sample(&request(1, 4)),
        SampleOutcome::Blocked(Blocked::BelowMinSize { have: 4, min: 8 })
    ));
    assert_eq!(s.handle_experience(&proto::encode(&batch(5, 20)), now), Ok(20));
    let b = sample(&mut s, 16);
    assert_eq!((b.len(), b.request_id, b.learner_step), (16, 1, 100));
    assert_rows_are_inserted_transitions(&b);
    let c = s.counters();
    assert_eq!(
        (c.insert_messages, c.inserted_transitions, c.sampled_batches, c.sampled_transitions),
        (2, 24, 1, 16)
    );
    match s.try_sample(&request(2, 17)) {
        SampleOutcome::Refused(RefusalReason::BatchTooLarge { requested: 17, max: 16 }) => {}
        other => panic!("{other:?}"),
    }
    assert_eq!(s.counters().refused.get("batch_too_large"), Some(&1));
}

#[test]
fn priority_updates_apply_and_go_stale_after_overwrite() {
    let cfg = cfg();
    let mut s = service(&cfg);
    let now = Instant::now();
    s.handle_experience(&proto::encode(&batch(0, 16)), now).unwrap();
    let b = sample(&mut s, 8);
    let update = PriorityUpdate {
        learner_step: 1,
        slots: b.slots.clone(),
        generations: b.generations.clone(),
        td_errors: vec![100.0; 8],
    };
    let outcome = s.handle_priorities(&proto::encode(&update), now).unwrap();
    assert_eq!(outcome.applied, 8);
    let top = s.buffer().top_k(1)[0];
    assert!(b.slots.contains(&top.id.slot));
    // Overwrite the whole ring: the same update is now stale everywhere.
    s.handle_experience(&proto::encode(&batch(100, 32)), now).unwrap();
    s.handle_experience(&proto::encode(&batch(132, 32)), now).unwrap();
    let outcome = s.handle_priorities(&proto::encode(&update), now).unwrap();
    assert_eq!((outcome.applied, outcome.stale), (0, 8));
    assert_eq!((s.counters().priorities_applied, s.counters().priorities_stale), (8, 8));
    let out_of_range =
        PriorityUpdate { slots: vec![64], generations: vec![0], td_errors: vec![1.0], ..update };
    let rejected = s.handle_priorities(&proto::encode(&out_of_range), now).unwrap_err();
    assert_eq!(rejected.key(), "priorities/slot_range");
}

#[test]
fn bad_input_is_counted_by_reason_and_changes_nothing() {
    let cfg = cfg();
    let mut s = service(&cfg);
    let now = Instant::now();
    let good = proto::encode(&batch(0, 4));
    let mut checksum = good.clone();
    let last = checksum.len() - 1;
    checksum[last] ^= 0x40;
    let mut version = good.clone();
    version[2] = 9;
    let mut nan = batch(0, 4);
    nan.transitions.rewards[2] = f32::NAN;
    let mut negative_td = batch(0, 4);
    negative_td.td_errors[0] = -1.0;
    let wrong_dims = ExperienceBatch {
        transitions: Transitions { obs_dim: 4, act_dim: 2, ..Transitions::with_capacity(4, 2, 0) },
        ..batch(0, 0)
    };
    let mut wrong_dims = wrong_dims;
    wrong_dims
        .transitions
        .push(proto::Transition {
            observation: &[0.0; 4],
            action: &[0.0; 2],
            reward: 0.0,
            next_observation: &[0.0; 4],
            terminated: false,
        })
        .unwrap();
    wrong_dims.td_errors = vec![0.0];
    let step = GlobalStep {
        learner_step: 1,
        weights_version: 1,
        env_steps_per_learner_step: 1,
        warm_up_share: 0,
        min_weights_version: 0,
        live_executors: 1,
    };
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (vec![1, 2, 3], "experience/truncated"),
        (vec![0xAB; 64], "experience/bad_magic"),
        (good[..good.len() - 3].to_vec(), "experience/truncated"),
        (checksum, "experience/checksum"),
        (version, "experience/bad_version"),
        (proto::encode(&step), "experience/wrong_kind"),
        (proto::encode(&nan), "experience/non_finite"),
        (proto::encode(&negative_td), "experience/negative"),
        (proto::encode(&wrong_dims), "experience/dims"),
        (proto::encode(&batch(0, 33)), "experience/too_large"),
        (vec![0; cfg.max_experience_bytes() as usize + 1], "experience/too_large"),
    ];
    for (bytes, key) in &cases {
        let rejection = s.handle_experience(bytes, now).unwrap_err();
        assert_eq!(rejection.key(), *key, "{}", rejection.detail);
    }
    assert_eq!(s.buffer().len(), 0);
    assert_eq!(s.rejects().total(), cases.len() as u64);
    assert_eq!(s.rejects().counts().get("experience/truncated"), Some(&2));
    let rejection = s.decode_request(Some(&proto::encode(&step)), now).unwrap_err();
    assert_eq!(rejection.key(), "sample/wrong_kind");
    assert_eq!(s.decode_request(None, now).unwrap_err().key(), "sample/truncated");
    assert_eq!(s.handle_experience(&good, now), Ok(4), "still serving");
    assert_eq!(proto::peek_kind(&good), Ok(MessageKind::ExperienceBatch));
}

#[test]
fn rate_limit_blocks_and_inserts_release() {
    let cfg =
        ReplayServerConfig { samples_per_insert: Some(1.0), samples_per_insert_tolerance: 16.0, ..cfg() };
    let mut s = service(&cfg);
    let now = Instant::now();
    s.handle_experience(&proto::encode(&batch(0, 8)), now).unwrap();
    sample(&mut s, 16);
    let SampleOutcome::Blocked(blocked) = s.try_sample(&request(2, 8)) else { panic!("not blocked") };
    assert_eq!(blocked.missing_inserts(), 8);
    s.handle_experience(&proto::encode(&batch(8, 8)), now).unwrap();
    sample(&mut s, 8);
}

#[test]
fn restored_service_continues_the_same_sample_sequence() {
    let cfg = cfg();
    let mut a = service(&cfg);
    let now = Instant::now();
    a.handle_experience(&proto::encode(&batch(0, 30)), now).unwrap();
    sample(&mut a, 16);
    let mut bytes = Vec::new();
    let sidecar = a.next_sidecar(1);
    snapshot::write_to(&mut bytes, a.buffer(), &sidecar).unwrap();
    let (buffer, sidecar) = snapshot::read_from(&mut &bytes[..], cfg.buffer.clone(), cfg.dims()).unwrap();
    let (mut b, resumed) = Service::new(&cfg, buffer, Some(sidecar));
    assert_eq!(resumed, Resumed::Continued);
    assert_eq!(b.counters(), a.counters());
    assert_eq!(b.limiter().counters(), a.limiter().counters());
    assert_eq!(b.snapshot_sequence(), 1);
    for _ in 0..3 {
        assert_eq!(sample(&mut a, 16), sample(&mut b, 16));
    }
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("replay-server-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("replay.snap")
}

fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn replica_snapshot_equals_the_live_buffer_at_the_request() {
    let cfg = cfg();
    let path = temp_path("replica");
    let mut s = service(&cfg);
    let replica_buffer = ReplayBuffer::new(cfg.buffer.clone(), cfg.dims()).unwrap();
    let replica = Replica::start(replica_buffer, FileWriter::new(path.clone()), 1 << 20).unwrap();
    s.attach_replica(replica.link());
    let now = Instant::now();
    for i in 0..6 {
        s.handle_experience(&proto::encode(&batch(i * 20, 20)), now).unwrap();
        let b = sample(&mut s, 16);
        let td_errors = (0..16).map(|j| (i * 16 + j) as f32).collect();
        let update =
            PriorityUpdate { learner_step: 1, slots: b.slots, generations: b.generations, td_errors };
        s.handle_priorities(&proto::encode(&update), now).unwrap();
    }
    assert!(s.request_snapshot(5));
    let expected: Vec<(SlotRef, f64, f32)> = s
        .buffer()
        .live_slots()
        .map(|id| {
            let view = s.buffer().get(id).unwrap();
            (id, view.priority, view.reward)
        })
        .collect();
    let counters = s.buffer().counters();
    // Mutations after the request must not leak into the snapshot.
    s.handle_experience(&proto::encode(&batch(500, 10)), now).unwrap();
    let link = s.replica().unwrap().clone();
    wait_until("the snapshot", || link.log().written == 1 && link.lag_bytes() == 0);
    drop(s.detach_replica());
    let log = replica.stop();
    assert_eq!((log.written, log.failed, log.last_sequence), (1, 0, 1));
    let (restored, sidecar) = snapshot::read_file(&path, cfg.buffer.clone(), cfg.dims()).unwrap().unwrap();
    assert_eq!(sidecar.sequence, 1);
    assert_eq!(restored.counters(), counters);
    let got: Vec<(SlotRef, f64, f32)> = restored
        .live_slots()
        .map(|id| {
            let view = restored.get(id).unwrap();
            (id, view.priority, view.reward)
        })
        .collect();
    assert_eq!(got, expected);
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
}

#[test]
fn max_rule_ignores_the_executors_td_errors() {
    let cfg = ReplayServerConfig { initial_priority: InitialPriority::Max, ..cfg() };
    let mut s = service(&cfg);
    s.handle_experience(&proto::encode(&batch(0, 16)), Instant::now()).unwrap();
    let stats = s.buffer().priority_stats().unwrap();
    assert_eq!((stats.min, stats.max), (1.0, 1.0), "an empty buffer's maximum is 1");
}

/// Batch `seq` of executor 0's stream 5, holding transitions `10 × seq ..`.
fn streamed(seq: u64) -> ExperienceBatch {
    ExperienceBatch { stream: 5, seq, ..batch(seq as u32 * 10, 4) }
}

#[test]
fn a_streams_batches_are_stored_once_and_a_snapshot_makes_them_durable() {
    let cfg = cfg();
    let path = temp_path("durable");
    let mut s = service(&cfg);
    let replica_buffer = ReplayBuffer::new(cfg.buffer.clone(), cfg.dims()).unwrap();
    let replica = Replica::start(replica_buffer, FileWriter::new(path.clone()), 1 << 20).unwrap();
    s.attach_replica(replica.link());
    let now = Instant::now();
    let send = |s: &mut Service, seq| s.handle_experience(&proto::encode(&streamed(seq)), now).unwrap();
    assert_eq!((send(&mut s, 0), send(&mut s, 1), send(&mut s, 0)), (4, 4, 0), "the re-send is recognised");
    assert_eq!((s.counters().duplicate_batches, s.counters().duplicate_transitions), (1, 4));
    assert_eq!(s.buffer().len(), 8);
    assert!(s.request_snapshot(5));
    send(&mut s, 2); // after the snapshot: not durable yet
    let link = s.replica().unwrap().clone();
    wait_until("the snapshot", || link.log().written == 1);
    let durable = link.log().durable.unwrap();
    assert_eq!(durable.durable_below(0, 5), Some(2));
    drop(s.detach_replica());
    replica.stop();

    // Restarted from that snapshot, the executor re-sends all it still holds: 1 and 2.
    let (buffer, sidecar) = snapshot::read_file(&path, cfg.buffer.clone(), cfg.dims()).unwrap().unwrap();
    assert_eq!(sidecar.durable_marks(), durable);
    let (mut restored, _) = Service::new(&cfg, buffer, Some(sidecar));
    assert_eq!((send(&mut restored, 1), send(&mut restored, 2)), (0, 4));
    assert_eq!(restored.buffer().len(), 12, "every batch once: 0, 1 from the snapshot, 2 re-sent");
    assert_eq!(restored.streams().marks()[0].durable_below, 3);
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
}

#[test]
fn unstreamed_batches_are_never_deduplicated() {
    let mut s = service(&cfg());
    let now = Instant::now();
    for _ in 0..2 {
        assert_eq!(s.handle_experience(&proto::encode(&batch(0, 4)), now).unwrap(), 4);
    }
    assert_eq!((s.buffer().len(), s.counters().duplicate_batches), (8, 0));
    assert!(s.streams().is_empty());
}

#[test]
fn a_refused_streamed_batch_is_decided_as_refused_not_stored() {
    let mut s = service(&cfg());
    let now = Instant::now();
    let too_large = ExperienceBatch { stream: 5, seq: 1, ..batch(10, cfg().max_insert_transitions + 1) };
    assert_eq!(s.accept_experience(Ok(streamed(0)), now).unwrap(), 4);
    assert!(s.accept_experience(Ok(too_large.clone()), now).is_err(), "too large: refused");
    assert_eq!(s.accept_experience(Ok(streamed(2)), now).unwrap(), 4);
    // Decided, so the spool releases it and a re-send is a duplicate; but refused, not stored.
    assert_eq!(s.streams().marks()[0].durable_below, 3);
    assert_eq!(s.accept_experience(Ok(too_large), now).unwrap(), 0);
    assert!(s.streams().refused(0, 5, 1));
    assert!(!s.streams().refused(0, 5, 0) && !s.streams().refused(0, 5, 2));
    assert_eq!(s.buffer().len(), 8);
}
