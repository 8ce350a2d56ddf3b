//! The wire contract of distributed SAC-LSP: every message, every key expression, and the one codec.
//! No I/O: processes hand [`encode`]d bytes to zenoh and [`decode`] what they receive.
//!
//! # Topics
//!
//! Every key lives under `rl/<run_id>/` ([`RunId`], [`topics`]); `<id>` is a decimal `u32`.
//!
//! | key under `rl/<run>/`              | message                                               | publisher                                        | subscribers                                                  |
//! |------------------------------------|-------------------------------------------------------|--------------------------------------------------|--------------------------------------------------------------|
//! | `experience/<executor_id>`         | [`ExperienceBatch`]                                   | executor                                         | replay server (`experience/*`)                               |
//! | `replay/sample` (queryable)        | [`SampleRequest`] → [`SampleReply`]                   | learner queries                                  | replay server replies                                        |
//! | `replay/priorities`                | [`PriorityUpdate`]                                    | learner                                          | replay server                                                |
//! | `replay/durable`                   | [`DurableMarks`]                                      | replay server                                    | executors (spools)                                           |
//! | `replay/state` (queryable, `?k=N`) | [`StatsReport`] (state, newest cut, top-k priorities) | learner and executors query (deterministic mode) | replay server replies                                        |
//! | `params/publish`                   | [`WeightsSnapshot`]                                   | learner                                          | param server                                                 |
//! | `params/weights` (queryable)       | [`WeightsSnapshot`] (`?version=V`)                    | param server replies                             | executors query on a newer version                           |
//! | `params/frozen` (queryable)        | [`FrozenLevels`] (hierarchies only)                   | param server replies                             | executors query once                                         |
//! | `control/learner`                  | [`LearnerStep`]                                       | learner                                          | param server                                                 |
//! | `control/step`                     | [`GlobalStep`]                                        | param server                                     | executors, learner, monitor                                  |
//! | `control/barrier/<executor_id>`    | [`BarrierReport`]                                     | executor                                         | param server, monitor                                        |
//! | `eval`                             | [`EvalReport`]                                        | learner                                          | monitor                                                      |
//! | `stats/<role>/<id>`                | [`StatsReport`]                                       | every process                                    | monitor (`stats/**`)                                         |
//! | `episodes/<executor_id>`           | [`EpisodeReport`]                                     | executor                                         | monitor (`episodes/*`)                                       |
//! | `liveliness/<role>/<id>`           | zenoh liveliness token, no payload                    | every role                                       | param server (barrier), executors (replay server's), monitor |
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
pub mod durable;
pub mod error;
pub mod experience;
pub mod params;
pub mod sampling;
pub mod stats;
pub mod topics;

pub use check::{MAX_BATCH_LEN, MAX_DIM, MAX_NAME_LEN, MAX_STATS_ENTRIES, MAX_TEXT_LEN};
pub use codec::{FORMAT_VERSION, Message, MessageKind, decode, encode, peek_kind};
pub use control::{BarrierReport, EvalMode, EvalReport, GlobalStep, LearnerStep};
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
