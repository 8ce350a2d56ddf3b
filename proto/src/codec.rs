//! The one encode/decode pair every process uses, and the frame around bincode.
//!
//! ```text
//! offset  size  field
//!      0     2  magic b"SL"
//!      2     2  format version, u16 little-endian (FORMAT_VERSION)
//!      4     1  message kind (MessageKind)
//!      5     4  payload length, u32 little-endian (≤ MAX_PAYLOAD_BYTES)
//!      9     4  CRC32 (IEEE) of the payload, u32 little-endian
//!     13     …  payload: bincode 2, config::standard() (varint integers, little-endian)
//! ```
//!
//! The checksum is what makes every single-byte corruption detectable: a flipped byte inside a float
//! array still parses, and could still be finite. CRC32 catches every burst of up to 32 bits, so any
//! single damaged byte is reported as [`DecodeError::ChecksumMismatch`] before bincode runs.
//! It is not authentication: a sender that computes a valid CRC over garbage reaches bincode and
//! then [`Message::validate`], and both reject without panicking or allocating without bound.

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::{DecodeError, ValidationError};

/// First two bytes of every frame.
pub const MAGIC: [u8; 2] = *b"SL";
/// Wire format version; bump on any change to the frame or to any message's fields.
pub const FORMAT_VERSION: u16 = 4;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 13;
/// Largest payload accepted, and the bincode allocation limit while parsing one.
pub const MAX_PAYLOAD_BYTES: usize = 256 << 20;

/// The decode-side bincode configuration; the limit caps what a corrupted length prefix could make
/// bincode allocate. Encoding has no limit: `encode` must not fail, and `decode` rejects oversize frames.
type DecodeConfig = bincode::config::Configuration<
    bincode::config::LittleEndian,
    bincode::config::Varint,
    bincode::config::Limit<MAX_PAYLOAD_BYTES>,
>;
const DECODE_CONFIG: DecodeConfig = bincode::config::standard().with_limit::<MAX_PAYLOAD_BYTES>();

/// Which message a frame holds: one byte in the header, one variant per wire type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageKind {
    /// [`crate::ExperienceBatch`].
    ExperienceBatch = 1,
    /// [`crate::SampleRequest`].
    SampleRequest = 2,
    /// [`crate::SampleReply`].
    SampleReply = 3,
    /// [`crate::PriorityUpdate`].
    PriorityUpdate = 4,
    /// [`crate::WeightsSnapshot`].
    WeightsSnapshot = 5,
    /// [`crate::GlobalStep`].
    GlobalStep = 6,
    /// [`crate::BarrierReport`].
    BarrierReport = 7,
    /// [`crate::EpisodeReport`].
    EpisodeReport = 8,
    /// [`crate::StatsReport`].
    StatsReport = 9,
    /// [`crate::LearnerStep`].
    LearnerStep = 10,
    /// [`crate::EvalReport`].
    EvalReport = 11,
    /// [`crate::FrozenLevels`].
    FrozenLevels = 12,
    /// [`crate::DurableMarks`].
    DurableMarks = 13,
    /// [`crate::ReplayCut`].
    ReplayCut = 14,
}

impl MessageKind {
    /// Every kind, in wire-byte order.
    pub const ALL: [MessageKind; 14] = [
        MessageKind::ExperienceBatch,
        MessageKind::SampleRequest,
        MessageKind::SampleReply,
        MessageKind::PriorityUpdate,
        MessageKind::WeightsSnapshot,
        MessageKind::GlobalStep,
        MessageKind::BarrierReport,
        MessageKind::EpisodeReport,
        MessageKind::StatsReport,
        MessageKind::LearnerStep,
        MessageKind::EvalReport,
        MessageKind::FrozenLevels,
        MessageKind::DurableMarks,
        MessageKind::ReplayCut,
    ];

    /// The kind with this wire byte, if any.
    pub fn from_u8(byte: u8) -> Option<MessageKind> {
        MessageKind::ALL.into_iter().find(|kind| *kind as u8 == byte)
    }
}

impl std::fmt::Display for MessageKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self, f)
    }
}

/// A type that travels on the bus. Sealed: only this crate's wire types implement it, which is
/// what lets [`encode`] promise it cannot fail (every field is a plain value or a sized sequence).
pub trait Message: Serialize + DeserializeOwned + sealed::Sealed {
    /// The header byte identifying this type.
    const KIND: MessageKind;

    /// Checks the contract beyond what the types express: consistent lengths, sane dimensions,
    /// finite floats. [`decode`] runs it on every message; senders may call it to fail early.
    fn validate(&self) -> Result<(), ValidationError>;
}

pub(crate) mod sealed {
    /// Keeps [`super::Message`] implementable only inside this crate.
    pub trait Sealed {
        /// Payload bytes to reserve, so `encode` allocates the frame once: bulk messages grow a
        /// `Vec` through several reallocations otherwise. Only an estimate; too small merely costs a copy.
        fn payload_size_hint(&self) -> usize {
            64
        }
    }
}

/// Encodes `msg` into a framed buffer. Does not validate: the receiver is the trust boundary, and
/// tests need to send invalid messages. A sender that wants to know first calls [`Message::validate`].
///
/// Never panics. A payload over [`MAX_PAYLOAD_BYTES`] is still framed (its length saturates at
/// `u32::MAX`), and every receiver rejects it with [`DecodeError::PayloadTooLarge`].
pub fn encode<M: Message>(msg: &M) -> Vec<u8> {
    let mut buf = Vec::with_capacity(HEADER_LEN + msg.payload_size_hint());
    buf.extend_from_slice(&MAGIC);
    buf.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    buf.push(M::KIND as u8);
    buf.extend_from_slice(&[0; 8]); // length and checksum, filled in below
    // Serializing our sealed types into a Vec cannot fail: no limit is configured, every sequence
    // has a known length and no field has a fallible Serialize impl. Should that ever change, the
    // frame is sent with an empty payload, which every receiver rejects as Malformed.
    if bincode::serde::encode_into_std_write(msg, &mut buf, bincode::config::standard()).is_err() {
        buf.truncate(HEADER_LEN);
    }
    let payload_len = u32::try_from(buf.len() - HEADER_LEN).unwrap_or(u32::MAX);
    let crc = crc32fast::hash(&buf[HEADER_LEN..]);
    buf[5..9].copy_from_slice(&payload_len.to_le_bytes());
    buf[9..13].copy_from_slice(&crc.to_le_bytes());
    buf
}

/// Decodes a framed buffer as an `M`, checking header, size, checksum, parse and [`Message::validate`].
/// Every failure is a typed [`DecodeError`]; no input makes it panic.
pub fn decode<M: Message>(bytes: &[u8]) -> Result<M, DecodeError> {
    let payload = open_frame(bytes, M::KIND)?;
    let (msg, used): (M, usize) = bincode::serde::borrow_decode_from_slice(payload, DECODE_CONFIG)
        .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if used != payload.len() {
        return Err(DecodeError::TrailingBytes { extra: payload.len() - used });
    }
    msg.validate()?;
    Ok(msg)
}

/// Reads the kind of a frame after checking magic and version, without touching the payload; for a
/// subscriber that accepts several kinds on one key.
pub fn peek_kind(bytes: &[u8]) -> Result<MessageKind, DecodeError> {
    let header =
        bytes.get(..HEADER_LEN).ok_or(DecodeError::TooShort { needed: HEADER_LEN, found: bytes.len() })?;
    let magic = [header[0], header[1]];
    if magic != MAGIC {
        return Err(DecodeError::BadMagic { found: magic });
    }
    let version = u16::from_le_bytes([header[2], header[3]]);
    if version != FORMAT_VERSION {
        return Err(DecodeError::UnsupportedVersion { found: version, expected: FORMAT_VERSION });
    }
    MessageKind::from_u8(header[4]).ok_or(DecodeError::UnknownKind(header[4]))
}

/// Checks everything in the frame except the payload's meaning and returns the payload.
fn open_frame(bytes: &[u8], expected: MessageKind) -> Result<&[u8], DecodeError> {
    // Version before kind: another version may number its kinds differently.
    let found = peek_kind(bytes)?;
    if found != expected {
        return Err(DecodeError::WrongKind { found, expected });
    }
    let declared = u32::from_le_bytes([bytes[5], bytes[6], bytes[7], bytes[8]]);
    let declared_len = declared as usize;
    if declared_len > MAX_PAYLOAD_BYTES {
        return Err(DecodeError::PayloadTooLarge {
            declared: u64::from(declared),
            max: MAX_PAYLOAD_BYTES as u64,
        });
    }
    let needed = HEADER_LEN + declared_len;
    if bytes.len() < needed {
        return Err(DecodeError::TooShort { needed, found: bytes.len() });
    }
    if bytes.len() > needed {
        return Err(DecodeError::TrailingBytes { extra: bytes.len() - needed });
    }
    let expected_crc = u32::from_le_bytes([bytes[9], bytes[10], bytes[11], bytes[12]]);
    let payload = &bytes[HEADER_LEN..];
    let found_crc = crc32fast::hash(payload);
    if found_crc != expected_crc {
        return Err(DecodeError::ChecksumMismatch { expected: expected_crc, found: found_crc });
    }
    Ok(payload)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{GlobalStep, SampleRequest};

    fn step() -> GlobalStep {
        GlobalStep {
            learner_step: 300,
            weights_version: 200,
            env_steps_per_learner_step: 1,
            warm_up_share: 1000,
            min_weights_version: 0,
            live_executors: 8,
        }
    }

    /// Replaces the payload of `frame` and fixes up length and checksum, so bincode and validation see it.
    fn with_payload(frame: &[u8], payload: &[u8]) -> Vec<u8> {
        let mut out = frame[..HEADER_LEN].to_vec();
        out[5..9].copy_from_slice(&(payload.len() as u32).to_le_bytes());
        out[9..13].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
        out.extend_from_slice(payload);
        out
    }

    #[test]
    fn header_layout() {
        let frame = encode(&step());
        assert_eq!(&frame[..2], b"SL");
        assert_eq!(u16::from_le_bytes([frame[2], frame[3]]), FORMAT_VERSION);
        assert_eq!(frame[4], MessageKind::GlobalStep as u8);
        let len = u32::from_le_bytes(frame[5..9].try_into().unwrap()) as usize;
        assert_eq!(frame.len(), HEADER_LEN + len);
        assert_eq!(peek_kind(&frame), Ok(MessageKind::GlobalStep));
        assert_eq!(decode::<GlobalStep>(&frame), Ok(step()));
    }

    #[test]
    fn kinds_round_trip_through_their_byte() {
        for kind in MessageKind::ALL {
            assert_eq!(MessageKind::from_u8(kind as u8), Some(kind));
        }
        assert_eq!(MessageKind::from_u8(0), None);
        assert_eq!(MessageKind::from_u8(15), None);
    }

    #[test]
    fn rejects_wrong_kind_and_version() {
        let frame = encode(&step());
        assert_eq!(
            decode::<SampleRequest>(&frame),
            Err(DecodeError::WrongKind {
                found: MessageKind::GlobalStep,
                expected: MessageKind::SampleRequest
            })
        );
        let mut old = frame.clone();
        old[2..4].copy_from_slice(&0u16.to_le_bytes());
        assert_eq!(
            decode::<GlobalStep>(&old),
            Err(DecodeError::UnsupportedVersion { found: 0, expected: FORMAT_VERSION })
        );
        let mut unknown = frame;
        unknown[4] = 200;
        assert_eq!(decode::<GlobalStep>(&unknown), Err(DecodeError::UnknownKind(200)));
    }

    #[test]
    fn rejects_oversize_declaration_without_allocating() {
        let mut frame = encode(&step());
        frame[5..9].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(decode::<GlobalStep>(&frame), Err(DecodeError::PayloadTooLarge { .. })));
    }

    #[test]
    fn rejects_trailing_bytes_outside_and_inside_the_payload() {
        let frame = encode(&step());
        let mut longer = frame.clone();
        longer.push(0);
        assert_eq!(decode::<GlobalStep>(&longer), Err(DecodeError::TrailingBytes { extra: 1 }));
        let mut payload = frame[HEADER_LEN..].to_vec();
        payload.push(0);
        assert_eq!(
            decode::<GlobalStep>(&with_payload(&frame, &payload)),
            Err(DecodeError::TrailingBytes { extra: 1 })
        );
    }

    #[test]
    fn checksummed_garbage_is_malformed_not_a_panic() {
        let frame = encode(&step());
        // A varint tag byte 0xFF is not a valid u64 prefix in bincode's standard config.
        let garbage = with_payload(&frame, &[0xFF; 3]);
        assert!(matches!(decode::<GlobalStep>(&garbage), Err(DecodeError::Malformed(_))));
        let empty = with_payload(&frame, &[]);
        assert!(matches!(decode::<GlobalStep>(&empty), Err(DecodeError::Malformed(_))));
    }

    #[test]
    fn checksummed_invalid_contents_fail_validation() {
        let zero_k = GlobalStep { env_steps_per_learner_step: 0, ..step() };
        assert_eq!(
            decode::<GlobalStep>(&encode(&zero_k)),
            Err(DecodeError::Invalid(ValidationError::Zero { field: "env_steps_per_learner_step" }))
        );
    }
}
