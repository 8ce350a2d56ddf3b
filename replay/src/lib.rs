//! Prioritized experience replay, sans-IO: the core that the `replay-server` role wraps in zenoh and
//! that a single-machine trainer uses directly. No threads, clocks or sockets; the caller owns the
//! RNG, so every run is reproducible.
//!
//! Proportional prioritization as in Schaul et al. 2016 ("Prioritized Experience Replay") and the
//! dissertation's `sac-prior` code (`docs/sac-lsp.md` §8): p = (|δ| + ε)^α, P(i) = p_i / Σp, stratified
//! sampling over k equal segments, IS weights (N·P(i))^−β normalised by the batch maximum, β annealed
//! linearly (without the original's jump to 1.4), new transitions at the maximum priority.
//!
//! # Layout
//!
//! | file          | what                                                                        |
//! |---------------|-----------------------------------------------------------------------------|
//! | `config.rs`   | [`ReplayConfig`] (paper defaults, `validate`), [`Dims`], [`SamplingMode`]   |
//! | `buffer.rs`   | [`ReplayBuffer`]: `insert_batch`, `sample`, `update_priorities`, `get`      |
//! | `batch.rs`    | [`TransitionBatch`] in, [`SampledBatch`] out, [`SlotRef`], outcomes         |
//! | `storage.rs`  | ring of transitions over a FIFO of observation rows (obs stored once)       |
//! | `sum_tree.rs` | [`SumTree`]: sums and maxima of priorities, O(log n), no drift              |
//! | `schedule.rs` | [`BetaSchedule`]: linear β                                                  |
//! | `stats.rs`    | [`Counters`], priority min/max/mean, effective sample size, top-k           |
//! | `snapshot.rs` | versioned, checksummed snapshots to any `Write`, from any `Read`            |
//! | `error.rs`    | [`ConfigError`], [`ReplayError`], [`SnapshotError`]                         |
//!
//! # Identity of a transition
//!
//! A transition is named by a [`SlotRef`]: its ring slot and the slot's generation, which grows each
//! time the slot is overwritten. The learner sends the pair back with the new TD errors; an update
//! whose slot has been overwritten in the meantime is counted as stale and ignored.
//!
//! # Example
//!
//! ```
//! use rand::{SeedableRng, rngs::StdRng};
//! use replay::{Dims, ReplayBuffer, ReplayConfig, SampledBatch, TransitionBatch};
//!
//! let cfg = ReplayConfig { capacity_transitions: 1000, ..ReplayConfig::default() };
//! let mut buffer = ReplayBuffer::new(cfg, Dims { obs_dim: 2, act_dim: 1 })?;
//! // Two consecutive steps of one episode: s0 -> s1 -> s2.
//! buffer.insert_batch(TransitionBatch {
//!     observations: &[0.0, 0.0, 1.0, 1.0],
//!     actions: &[0.5, -0.5],
//!     rewards: &[1.0, 2.0],
//!     next_observations: &[1.0, 1.0, 2.0, 2.0],
//!     terminated: &[false, true],
//!     abs_td_errors: None,
//! })?;
//! let mut rng = StdRng::seed_from_u64(1);
//! let mut batch = SampledBatch::new();
//! buffer.sample(4, 0, &mut rng, &mut batch)?;
//! let new_abs_td_errors = [0.1, 2.0, 0.3, 0.0];
//! let outcome = buffer.update_priorities(&batch.slots, &batch.generations, &new_abs_td_errors)?;
//! assert_eq!(outcome.applied, 4);
//! # Ok::<(), replay::ReplayError>(())
//! ```

#![deny(missing_docs)]

mod batch;
mod buffer;
mod config;
mod error;
mod schedule;
mod snapshot;
mod stats;
mod storage;
mod sum_tree;
#[cfg(test)]
mod test_support;

pub use batch::{InsertOutcome, SampledBatch, SlotRef, TransitionBatch, TransitionView, UpdateOutcome};
pub use buffer::ReplayBuffer;
pub use config::{Dims, MAX_CAPACITY, ReplayConfig, SamplingMode};
pub use error::{ConfigError, ReplayError, Result, SnapshotError};
pub use schedule::BetaSchedule;
pub use snapshot::{SNAPSHOT_MAGIC, SNAPSHOT_VERSION};
pub use stats::{Counters, PriorityDigest, PriorityScan, PriorityStats, SlotPriority};
pub use sum_tree::SumTree;
