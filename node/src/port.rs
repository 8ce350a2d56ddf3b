//! A free loopback port for tests, benches and local runs that start a listener of their own.

use std::collections::hash_map::RandomState;
use std::hash::{BuildHasher, Hasher};
use std::net::TcpListener;

/// Ports tried: below Linux's ephemeral range (32768-60999), where outgoing connections take
/// their source ports, so a port found free here is not taken by some session's connect before its
/// listener binds it (binding port 0 picks from exactly that range).
const RANGE: std::ops::Range<u16> = 20_000..32_000;

/// A free TCP port on 127.0.0.1: picked at random in [`RANGE`] and checked by binding it (then
/// released for the caller's listener).
pub fn free_loopback_port() -> std::io::Result<u16> {
    let state = RandomState::new();
    let span = u64::from(RANGE.end - RANGE.start);
    for attempt in 0u64..200 {
        let mut hasher = state.build_hasher();
        hasher.write_u64(attempt);
        let port = RANGE.start + (hasher.finish() % span) as u16;
        if TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return Ok(port);
        }
    }
    // A crowded range: fall back to whatever the kernel picks.
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_port_is_free_and_in_range() {
        let port = free_loopback_port().unwrap();
        assert!(RANGE.contains(&port), "{port}");
        TcpListener::bind(("127.0.0.1", port)).expect("still free");
    }
}
