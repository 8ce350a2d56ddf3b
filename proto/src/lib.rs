//! The wire contract of distributed SAC-LSP: every message, every key expression, and the one codec.
//! No I/O: processes hand [`encode`]d bytes to zenoh and [`decode`] what they receive.
//!
//! # Topics
//!
//! Every key lives under `rl/<run_id>/` ([`RunId`], [`topics`]); `<id>` is a decimal `u32`.
//!
//! [`registry::TOPICS`] lists every topic family with its message, who writes it and who reads
//! it; the docs' key table (`docs/distributed.md`) and `deploy/certs.sh`'s access control are
//! generated from it.
//!
//! # Parts
//!
//! - [`codec`]: [`encode`]/[`decode`], the frame (magic, version, kind, length, CRC32, bincode 2
//!   payload) and the [`Message`] trait every wire type implements.
//! - [`topics`]: [`RunId`], [`Role`], [`Topic`] (key ⇄ topic) and the key builders and wildcards.
//! - [`experience`], [`durable`], [`sampling`], [`params`], [`control`], [`stats`]: one message
//!   family each.
//! - [`error`]: [`DecodeError`], [`ValidationError`], [`TopicError`].
//!
//! Bulk data is `f32`, stored as flat row-major `Vec<f32>` columns and written as one byte string each.
//! [`decode`] rejects, with a typed error and never a panic, any buffer that is truncated, corrupted
//! (checksum), from another format version, of another message kind, or whose contents break the
//! contract (lengths against dimensions, dimensions in 1..=[`MAX_DIM`], finite floats).
//!
//! ```
//! use proto::{GlobalStep, RunId, decode, encode, topics};
//!
//! let run = RunId::new("ant-seed0")?;
//! assert_eq!(topics::control_step(&run), "rl/ant-seed0/control/step");
//! let step = GlobalStep {
//!     learner_step: 1000,
//!     weights_version: 1000,
//!     env_steps_per_learner_step: 1,
//!     warm_up_share: 1250,
//!     min_weights_version: 0,
//!     live_executors: 8,
//! };
//! assert_eq!(step.allowance(0), 2250);
//! let bytes = encode(&step);
//! assert_eq!(decode::<GlobalStep>(&bytes)?, step);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod blob;
mod check;
pub mod codec;
pub mod control;
pub mod cut;
pub mod durable;
pub mod error;
pub mod experience;
pub mod params;
pub mod registry;
pub mod sampling;
pub mod stats;
pub mod topics;

pub use check::{MAX_BATCH_LEN, MAX_DIM, MAX_NAME_LEN, MAX_STATS_ENTRIES, MAX_TEXT_LEN};
pub use codec::{FORMAT_VERSION, Message, MessageKind, decode, encode, peek_kind};
pub use control::{BarrierReport, EvalMode, EvalReport, GlobalStep, LearnerStep};
pub use cut::{CutState, ReplayCut};
pub use durable::{DurableMarks, MAX_STREAM_MARKS, StreamMark};
pub use error::{DecodeError, Result, TopicError, ValidationError};
pub use experience::{ExperienceBatch, Transition, Transitions};
pub use params::{ContentHash, FrozenLevel, FrozenLevels, MAX_FROZEN_LEVELS, WeightsSnapshot};
pub use sampling::{
    DEFAULT_REQUEST_DEADLINE_MS, DEFAULT_TRANSITION_DIMS, PriorityUpdate, RefusalReason, SampleRefusal,
    SampleReply, SampleRequest, SampledBatch,
};
pub use stats::{BlockedReason, EpisodeReport, Metric, RejectCount, StatsReport};
pub use topics::{NodeId, Role, RunId, Topic, TopicSet};
