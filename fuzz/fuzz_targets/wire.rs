//! Every wire decoder on arbitrary bytes: as they come off the bus; as the payload of a
//! well-formed frame of every kind (past the magic, version, length and CRC checks, where bincode
//! and each message's `validate` run); and as mutations of valid messages of the richest kinds
//! (byte flips in the payload, the CRC fixed up, so the mutation reaches bincode and `validate`).
//! No input may panic or allocate without bound.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use proto::codec::{HEADER_LEN, MAGIC};
use proto::{
    BarrierReport, BlockedReason, DurableMarks, EpisodeReport, EvalReport, ExperienceBatch, FrozenLevels,
    GlobalStep, LearnerStep, MessageKind, Metric, PriorityUpdate, RejectCount, SampleReply, SampleRequest,
    SampledBatch, StatsReport, StreamMark, Transition, Transitions, WeightsSnapshot, decode, encode,
    peek_kind,
};

fn every_decoder(frame: &[u8]) {
    let _ = peek_kind(frame);
    let _ = decode::<ExperienceBatch>(frame);
    let _ = decode::<SampleRequest>(frame);
    let _ = decode::<SampleReply>(frame);
    let _ = decode::<PriorityUpdate>(frame);
    let _ = decode::<WeightsSnapshot>(frame);
    let _ = decode::<GlobalStep>(frame);
    let _ = decode::<BarrierReport>(frame);
    let _ = decode::<EpisodeReport>(frame);
    let _ = decode::<StatsReport>(frame);
    let _ = decode::<LearnerStep>(frame);
    let _ = decode::<EvalReport>(frame);
    let _ = decode::<FrozenLevels>(frame);
    let _ = decode::<DurableMarks>(frame);
}

/// `payload` in a frame of `kind` with a correct header and checksum (`proto::codec`'s layout).
fn framed(kind: MessageKind, payload: &[u8]) -> Vec<u8> {
    let mut frame = Vec::with_capacity(HEADER_LEN + payload.len());
    frame.extend_from_slice(&MAGIC);
    frame.extend_from_slice(&proto::FORMAT_VERSION.to_le_bytes());
    frame.push(kind as u8);
    frame.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    frame.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    frame.extend_from_slice(payload);
    frame
}

fn transitions(n: usize) -> Transitions {
    let mut t = Transitions::with_capacity(3, 2, n);
    for i in 0..n {
        let x = i as f32;
        let transition = Transition {
            observation: &[x, 1.0, 2.0],
            action: &[0.5, -0.5],
            reward: x,
            next_observation: &[x + 1.0, 1.0, 2.0],
            terminated: i == n - 1,
        };
        t.push(transition).expect("widths");
    }
    t
}

/// Valid frames of the kinds with variable-length fields.
fn valid() -> &'static [Vec<u8>] {
    static FRAMES: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    FRAMES.get_or_init(|| {
        let experience = ExperienceBatch {
            executor_id: 1,
            stream: 9,
            seq: 2,
            weights_version: 3,
            env_steps: 4,
            transitions: transitions(3),
            td_errors: vec![0.1, 0.2, 0.3],
        };
        let sampled = SampleReply::Batch(SampledBatch {
            request_id: 5,
            learner_step: 6,
            slots: vec![1, 2],
            generations: vec![0, 1],
            is_weights: vec![1.0, 0.5],
            transitions: transitions(2),
        });
        let mut stats = StatsReport::new(proto::NodeId { role: proto::Role::Executor, id: 2 }, 7);
        stats.metrics.push(Metric { name: "executor/env_steps".into(), value: 8.0 });
        stats.blocked.push(BlockedReason {
            what: "barrier".into(),
            why: "at the allowance".into(),
            since_ms: 9,
        });
        stats.rejected.push(RejectCount { reason: "weights/bad_body".into(), count: 1 });
        let weights = WeightsSnapshot {
            version: 10,
            learner_step: 10,
            safetensors: vec![8, 0, 0, 0, 0, 0, 0, 0, b'{', b'}'],
            stack: None,
        };
        let marks = DurableMarks {
            snapshot_sequence: 3,
            marks: vec![StreamMark { executor_id: 0, stream: 9, durable_below: 4 }],
        };
        vec![encode(&experience), encode(&sampled), encode(&stats), encode(&weights), encode(&marks)]
    })
}

/// `frame` with its payload bytes flipped as `edits` say (offset, xor) and its CRC fixed up.
fn mutated(frame: &[u8], edits: &[u8]) -> Vec<u8> {
    let mut frame = frame.to_vec();
    let len = frame.len() - HEADER_LEN;
    for edit in edits.chunks_exact(3) {
        let at = HEADER_LEN + u16::from_le_bytes([edit[0], edit[1]]) as usize % len;
        frame[at] ^= edit[2];
    }
    let crc = crc32fast::hash(&frame[HEADER_LEN..]);
    frame[9..13].copy_from_slice(&crc.to_le_bytes());
    frame
}

fuzz_target!(|data: &[u8]| {
    every_decoder(data);
    if let Some((&selector, rest)) = data.split_first() {
        let kind = MessageKind::ALL[selector as usize % MessageKind::ALL.len()];
        every_decoder(&framed(kind, rest));
        let frames = valid();
        every_decoder(&mutated(&frames[selector as usize % frames.len()], rest));
    }
});
