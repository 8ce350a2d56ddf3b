//! The replay server's snapshot reader (server sidecar, then the buffer's own snapshot) on arbitrary
//! bytes, for a small buffer: it must refuse what is not a snapshot of that buffer, never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use replay::{Dims, ReplayConfig};

fuzz_target!(|data: &[u8]| {
    let config = ReplayConfig { capacity_transitions: 64, ..ReplayConfig::default() };
    let _ = replay_server::read_snapshot(&mut &data[..], config, Dims { obs_dim: 3, act_dim: 2 });
});
