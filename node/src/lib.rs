//! What every process needs to join a run on the bus: command-line options ([`NodeArgs`]), the zenoh
//! session scoped to a run id ([`Bus`]), a shutdown signal that tests can trigger ([`Shutdown`]),
//! tracing set-up ([`telemetry`]), where a deterministic run resumes ([`Cut`]), and atomic, durable
//! file writes ([`durable`]). The run file is `run`'s ([`run::RunSpec`]).
//!
//! A role binary is a thin `main` over its library's `run(cfg, bus, shutdown)`; [`launch`] is that
//! `main`, written once for all roles.
#![deny(missing_docs)]

mod args;
mod bus;
mod clock;
mod cut;
pub mod durable;
mod endpoints;
mod error;
pub mod faults;
mod launch;
mod port;
mod rejects;
mod shutdown;
pub mod telemetry;

pub use args::{BusConfig, NodeArgs, ZenohMode};
pub use bus::{Bus, DEFAULT_QUEUE, decode_payload};
pub use clock::unix_ms;
pub use cut::{Cut, CutWait, ask_cut, wait_for_cut};
pub use endpoints::{Delivery, Incoming, Keyed, Publisher, Queryable, Subscriber};
pub use error::NodeError;
pub use faults::{Direction, Fault, Faults};
pub use launch::{launch, main};
pub use port::free_loopback_port;
pub use rejects::{Rejects, WARN_EVERY};
pub use shutdown::{Shutdown, ShutdownTrigger};
