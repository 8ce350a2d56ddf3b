//! Every wire decoder on arbitrary bytes: as they come off the bus, and as the payload of a
//! well-formed frame of every kind (past the magic, version, length and CRC checks, where bincode
//! and each message's `validate` run). No input may panic or allocate without bound.
#![no_main]

use libfuzzer_sys::fuzz_target;
use proto::{
    BarrierReport, DurableMarks, EpisodeReport, EvalReport, ExperienceBatch, FrozenLevels, GlobalStep,
    LearnerStep, MessageKind, PriorityUpdate, SampleReply, SampleRequest, StatsReport, WeightsSnapshot,
    decode, peek_kind,
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
    let mut frame = Vec::with_capacity(proto::codec::HEADER_LEN + payload.len());
    frame.extend_from_slice(&proto::codec::MAGIC);
    frame.extend_from_slice(&proto::FORMAT_VERSION.to_le_bytes());
    frame.push(kind as u8);
    frame.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    frame.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    frame.extend_from_slice(payload);
    frame
}

fuzz_target!(|data: &[u8]| {
    every_decoder(data);
    if let Some((&selector, payload)) = data.split_first() {
        let kind = MessageKind::ALL[selector as usize % MessageKind::ALL.len()];
        every_decoder(&framed(kind, payload));
    }
});
