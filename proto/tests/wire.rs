//! Every message type through the codec: round trips, and rejection without panic of every truncated
//! buffer, every single-byte corruption, wrong kinds and versions, and contents that break the contract.

use std::fmt::Debug;

use proto::codec::HEADER_LEN;
use proto::{
    BarrierReport, BlockedReason, DecodeError, EpisodeReport, EvalReport, ExperienceBatch, GlobalStep,
    LearnerStep, Message, MessageKind, NodeId, PriorityUpdate, RefusalReason, RejectCount, Role,
    SampleRefusal, SampleReply, SampleRequest, SampledBatch, StatsReport, Transitions, ValidationError,
    WeightsSnapshot, decode, encode,
};

/// Deterministic data without a `rand` dependency (xorshift64*).
struct Noise(u64);

impl Noise {
    fn f32(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40;
        bits as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }

    fn vec(&mut self, n: usize) -> Vec<f32> {
        (0..n).map(|_| self.f32()).collect()
    }
}

fn transitions(n: usize, obs_dim: u32, act_dim: u32) -> Transitions {
    let mut noise = Noise(0x9E37_79B9_7F4A_7C15 ^ n as u64);
    let (o, a) = (obs_dim as usize, act_dim as usize);
    Transitions {
        obs_dim,
        act_dim,
        observations: noise.vec(n * o),
        actions: noise.vec(n * a),
        rewards: noise.vec(n),
        next_observations: noise.vec(n * o),
        terminated: (0..n).map(|i| i % 7 == 3).collect(),
    }
}

fn experience(n: usize, obs_dim: u32, act_dim: u32) -> ExperienceBatch {
    ExperienceBatch {
        executor_id: 3,
        stream: 0,
        seq: 41,
        weights_version: 12_000,
        env_steps: 1_234_567,
        transitions: transitions(n, obs_dim, act_dim),
        td_errors: (0..n).map(|i| i as f32 * 0.25).collect(),
    }
}

fn sampled(n: usize) -> SampledBatch {
    SampledBatch {
        request_id: 9,
        learner_step: 12_345,
        slots: (0..n as u64).map(|i| i * 1009 % 1_000_000).collect(),
        generations: (0..n as u64).map(|i| i % 3).collect(),
        is_weights: (0..n).map(|i| 1.0 / (1.0 + i as f32)).collect(),
        transitions: transitions(n, 5, 2),
    }
}

fn stats() -> StatsReport {
    let mut report = StatsReport::new(NodeId { role: Role::Replay, id: 0 }, 1_767_225_600_000);
    report.push_metric("replay/size_transitions", 250_000.0);
    report.push_metric("replay/samples_per_insert", 31.5);
    report.blocked.push(BlockedReason {
        what: "replay/insert".into(),
        why: "waiting for learner".into(),
        since_ms: 7,
    });
    report.rejected.push(RejectCount { reason: "decode/checksum".into(), count: 2 });
    report
}

/// Round trip, then every truncation and every single-byte change (at `stride`, plus the whole
/// header and the last byte) must be an error.
fn check_message<M: Message + PartialEq + Debug>(msg: &M, stride: usize) {
    assert_eq!(msg.validate(), Ok(()), "fixture must be valid");
    let mut frame = encode(msg);
    assert_eq!(decode::<M>(&frame).as_ref(), Ok(msg), "round trip");

    for len in 0..frame.len() {
        assert!(decode::<M>(&frame[..len]).is_err(), "{:?}: truncation to {len} accepted", M::KIND);
    }
    let last = frame.len() - 1;
    let positions = (0..frame.len()).filter(|i| *i < HEADER_LEN || i % stride == 0 || *i == last);
    for i in positions {
        for mask in [0x01, 0x80, 0xFF] {
            frame[i] ^= mask;
            assert!(decode::<M>(&frame).is_err(), "{:?}: byte {i} ^ {mask:#04x} accepted", M::KIND);
            frame[i] ^= mask;
        }
    }
    assert_eq!(decode::<M>(&frame).as_ref(), Ok(msg), "frame restored");
}

/// With a recomputed checksum, mutated payloads reach bincode and validation: they may decode (to
/// something valid) or fail, but must never panic.
fn check_checksummed_mutations<M: Message + Debug>(msg: &M, stride: usize) {
    let frame = encode(msg);
    let (mut accepted, mut rejected) = (0, 0);
    for i in (HEADER_LEN..frame.len()).step_by(stride) {
        for mask in [0x01, 0x40, 0xFF] {
            let mut payload = frame[HEADER_LEN..].to_vec();
            payload[i - HEADER_LEN] ^= mask;
            match decode::<M>(&reframe(&frame, &payload)) {
                Ok(decoded) => {
                    assert_eq!(decoded.validate(), Ok(()));
                    accepted += 1;
                }
                Err(_) => rejected += 1,
            }
        }
    }
    // Both outcomes, or the mutations never reached the parser and validation.
    assert!(accepted > 0 && rejected > 0, "{:?}: {accepted} accepted, {rejected} rejected", M::KIND);
}

/// `frame`'s header around a new payload, with length and checksum fixed up.
fn reframe(frame: &[u8], payload: &[u8]) -> Vec<u8> {
    let mut out = frame[..HEADER_LEN].to_vec();
    out[5..9].copy_from_slice(&(payload.len() as u32).to_le_bytes());
    out[9..13].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// Bitwise CRC32 (IEEE), to pin the header's checksum to the standard one independently of crc32fast.
fn crc32_ieee_bitwise(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

fn invalid<T>(e: ValidationError) -> Result<T, DecodeError> {
    Err(DecodeError::Invalid(e))
}

fn nan_at<T>(field: &'static str, index: usize) -> Result<T, DecodeError> {
    invalid(ValidationError::NonFinite { field, index })
}

#[test]
fn experience_batch_small_exhaustive() {
    let msg = experience(4, 3, 2);
    check_message(&msg, 1);
    check_checksummed_mutations(&msg, 1);
}

#[test]
fn experience_batch_ant_sized() {
    let msg = experience(128, 105, 8);
    assert_eq!(msg.len(), 128);
    check_message(&msg, 97);
    check_checksummed_mutations(&msg, 997);
}

#[test]
fn sample_request() {
    check_message(&SampleRequest { request_id: 77, learner_step: 1 << 40, batch_size: 256 }, 1);
}

#[test]
fn sample_reply_batch() {
    let msg = SampleReply::Batch(sampled(6));
    check_message(&msg, 1);
    check_checksummed_mutations(&msg, 1);
}

#[test]
fn sample_reply_refusals() {
    let reasons = [
        RefusalReason::BelowMinSize { have: 512, min: 10_000 },
        RefusalReason::RateLimited { samples_per_insert: 300.0, max_samples_per_insert: 256.0 },
        RefusalReason::BatchTooLarge { requested: 100_000, max: 65_536 },
        RefusalReason::ShuttingDown,
        RefusalReason::Other { detail: "sum tree rebuilding".into() },
    ];
    for reason in reasons {
        let msg = SampleReply::Refused(SampleRefusal { request_id: 4, reason, retry_after_ms: 50 });
        check_message(&msg, 1);
        check_checksummed_mutations(&msg, 1);
    }
}

#[test]
fn priority_update() {
    let msg = PriorityUpdate {
        learner_step: 99,
        slots: vec![0, 5, 1 << 33],
        generations: vec![0, 1, 250],
        td_errors: vec![0.0, 1.5, 1e-6],
    };
    check_message(&msg, 1);
    check_checksummed_mutations(&msg, 1);
}

#[test]
fn weights_snapshot() {
    // Not a real safetensors file: the bytes are opaque to the codec.
    let msg = WeightsSnapshot {
        version: 5000,
        learner_step: 5001,
        safetensors: (0..=255).cycle().take(3000).collect(),
        stack: Some(proto::ContentHash([9; 32])),
    };
    check_message(&msg, 7);
}

#[test]
fn frozen_levels() {
    let msg = proto::FrozenLevels {
        content_hash: proto::ContentHash([3; 32]),
        levels: vec![
            proto::FrozenLevel { safetensors: (0..=255).cycle().take(2000).collect() },
            proto::FrozenLevel { safetensors: vec![1; 40] },
        ],
    };
    check_message(&msg, 7);
}

#[test]
fn control_messages() {
    let step = GlobalStep {
        learner_step: 10,
        weights_version: 8,
        env_steps_per_learner_step: 1,
        warm_up_share: 1250,
        min_weights_version: 0,
        live_executors: 8,
    };
    check_message(&step, 1);
    check_message(&LearnerStep { learner_step: 10, weights_version: 8, starved: false }, 1);
    let eval = EvalReport {
        epoch: 3,
        learner_step: 3000,
        episodes: 1,
        mean_return: 812.5,
        mean_length: 1000.0,
        std_return: 0.0,
        mode: proto::EvalMode::ZeroLatent,
        goal_success: None,
    };
    check_message(&eval, 1);
    check_message(&EvalReport { goal_success: Some(0.25), ..eval }, 1);
    assert!(EvalReport { mean_return: f64::NAN, ..eval }.validate().is_err());
    for bad in [-0.1, 1.5, f64::NAN] {
        assert!(EvalReport { goal_success: Some(bad), ..eval }.validate().is_err(), "{bad}");
    }
    let barrier = BarrierReport {
        executor_id: 2,
        env_steps: 50_000,
        allowed_env_steps: 50_001,
        learner_step_seen: 49,
        joined_at: 0,
        weights_version: 40,
        blocked: true,
        blocked_ms_total: 1234,
    };
    check_message(&barrier, 1);
    check_checksummed_mutations(&barrier, 1);
}

#[test]
fn stats_and_episodes() {
    check_message(&stats(), 1);
    check_checksummed_mutations(&stats(), 1);
    let episode = EpisodeReport {
        executor_id: 1,
        episode: 17,
        episode_return: 2345.5,
        length: 1000,
        terminated: false,
        env_steps: 18_000,
        weights_version: 300,
    };
    check_message(&episode, 1);
}

#[test]
fn header_checksum_is_standard_crc32() {
    let frame = encode(&experience(4, 3, 2));
    assert_eq!(crc32_ieee_bitwise(b"123456789"), 0xCBF4_3926);
    assert_eq!(frame[9..13], crc32_ieee_bitwise(&frame[HEADER_LEN..]).to_le_bytes());
}

#[test]
fn wrong_kind_is_rejected() {
    let frame = encode(&experience(2, 3, 2));
    assert_eq!(
        decode::<SampleRequest>(&frame),
        Err(DecodeError::WrongKind {
            found: MessageKind::ExperienceBatch,
            expected: MessageKind::SampleRequest
        })
    );
    assert_eq!(proto::peek_kind(&frame), Ok(MessageKind::ExperienceBatch));
}

#[test]
fn other_version_is_rejected() {
    let mut frame = encode(&experience(2, 3, 2));
    frame[2..4].copy_from_slice(&(proto::FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(
        decode::<ExperienceBatch>(&frame),
        Err(DecodeError::UnsupportedVersion {
            found: proto::FORMAT_VERSION + 1,
            expected: proto::FORMAT_VERSION
        })
    );
}

#[test]
fn non_finite_floats_are_rejected_on_decode() {
    for (field, index) in [("observations", 7), ("actions", 3), ("rewards", 1), ("next_observations", 11)] {
        let mut msg = experience(4, 3, 2);
        let column = match field {
            "observations" => &mut msg.transitions.observations,
            "actions" => &mut msg.transitions.actions,
            "rewards" => &mut msg.transitions.rewards,
            _ => &mut msg.transitions.next_observations,
        };
        column[index] = if index % 2 == 0 { f32::NAN } else { f32::NEG_INFINITY };
        assert_eq!(decode::<ExperienceBatch>(&encode(&msg)), nan_at(field, index), "{field}");
    }
    let mut msg = experience(4, 3, 2);
    msg.td_errors[2] = f32::INFINITY;
    assert_eq!(decode::<ExperienceBatch>(&encode(&msg)), nan_at("td_errors", 2));

    let mut batch = sampled(3);
    batch.is_weights[0] = f32::NAN;
    assert_eq!(decode::<SampleReply>(&encode(&SampleReply::Batch(batch))), nan_at("is_weights", 0));
    let update =
        PriorityUpdate { learner_step: 1, slots: vec![1], generations: vec![1], td_errors: vec![f32::NAN] };
    assert_eq!(decode::<PriorityUpdate>(&encode(&update)), nan_at("td_errors", 0));
    let mut report = stats();
    report.metrics[1].value = f64::NAN;
    assert_eq!(decode::<StatsReport>(&encode(&report)), nan_at("metrics", 1));
}

#[test]
fn inconsistent_sizes_are_rejected_on_decode() {
    let mut short = experience(4, 3, 2);
    short.transitions.observations.truncate(11);
    assert_eq!(
        decode::<ExperienceBatch>(&encode(&short)),
        invalid(ValidationError::LengthMismatch { field: "observations", expected: 12, found: 11 })
    );
    let mut flags = experience(4, 3, 2);
    flags.transitions.terminated.push(true);
    assert_eq!(
        decode::<ExperienceBatch>(&encode(&flags)),
        invalid(ValidationError::LengthMismatch { field: "terminated", expected: 4, found: 5 })
    );
    let mut td = experience(4, 3, 2);
    td.td_errors.pop();
    assert_eq!(
        decode::<ExperienceBatch>(&encode(&td)),
        invalid(ValidationError::LengthMismatch { field: "td_errors", expected: 4, found: 3 })
    );
    let mut wide = experience(1, 3, 2);
    wide.transitions.obs_dim = 5000;
    assert_eq!(
        decode::<ExperienceBatch>(&encode(&wide)),
        invalid(ValidationError::BadDimension { field: "obs_dim", value: 5000, max: proto::MAX_DIM })
    );
    let mut slots = sampled(3);
    slots.slots.pop();
    assert_eq!(
        decode::<SampleReply>(&encode(&SampleReply::Batch(slots))),
        invalid(ValidationError::LengthMismatch { field: "slots", expected: 3, found: 2 })
    );
    let empty = WeightsSnapshot { version: 1, learner_step: 1, safetensors: Vec::new(), stack: None };
    assert_eq!(
        decode::<WeightsSnapshot>(&encode(&empty)),
        invalid(ValidationError::Empty { field: "safetensors" })
    );
    let zero = SampleRequest { request_id: 1, learner_step: 1, batch_size: 0 };
    assert_eq!(
        decode::<SampleRequest>(&encode(&zero)),
        invalid(ValidationError::Empty { field: "batch_size" })
    );
}

#[test]
fn arbitrary_bytes_never_panic() {
    let mut noise = Noise(42);
    for len in 0..512 {
        let mut bytes: Vec<u8> = (0..len).map(|_| (noise.f32().to_bits() >> 7) as u8).collect();
        if len >= 5 {
            // Give most of them a plausible header so the later checks run too.
            bytes[..4].copy_from_slice(&[b'S', b'L', 1, 0]);
            bytes[4] = (len % 10) as u8;
        }
        let _ = decode::<ExperienceBatch>(&bytes);
        let _ = decode::<SampleReply>(&bytes);
        let _ = decode::<StatsReport>(&bytes);
        if len > HEADER_LEN {
            let _ = decode::<StatsReport>(&reframe(&bytes, &bytes[HEADER_LEN..]));
            let _ = decode::<SampleReply>(&reframe(&bytes, &bytes[HEADER_LEN..]));
        }
    }
}
