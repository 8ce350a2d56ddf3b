//! How the replay server scans priorities: `replay`'s [`PriorityScan`] a [`CHUNK`] at a time, so
//! that no single lock hold is long (at 1M transitions a whole scan takes several milliseconds).

pub use replay::{PriorityDigest, PriorityScan};

/// Transitions examined per lock hold: ~0.4 ms (measured ~48 ns per transition at 1M, release).
pub const CHUNK: u64 = 8192;
