use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::*;
use crate::batch::SampledBatch;
use crate::config::SamplingMode;
use crate::error::ConfigError;
use crate::test_support::OwnedBatch;

const DIMS: Dims = Dims { obs_dim: 4, act_dim: 3 };

fn config() -> ReplayConfig {
    ReplayConfig { capacity_transitions: 50, observation_rows: Some(70), ..ReplayConfig::default() }
}

/// A buffer that has wrapped, evicted early, sampled and updated priorities.
fn used_buffer() -> ReplayBuffer {
    let mut b = ReplayBuffer::new(config(), DIMS).unwrap();
    let mut rng = StdRng::seed_from_u64(1);
    let mut out = SampledBatch::new();
    for call in 0..40u32 {
        let n = rng.random_range(1..6);
        let batch = OwnedBatch::run(DIMS, call % 3, call * 10, n);
        let batch = if call % 2 == 0 {
            let errors = (0..n).map(|_| rng.random_range(0.0..5.0)).collect();
            batch.with_td(errors)
        } else {
            batch
        };
        b.insert_batch(batch.batch()).unwrap();
        b.sample(8, u64::from(call), &mut rng, &mut out).unwrap();
        let errors: Vec<f32> = (0..8).map(|_| rng.random_range(0.0..5.0)).collect();
        b.update_priorities(&out.slots, &out.generations, &errors).unwrap();
    }
    let c = b.counters();
    assert!(c.inserted_total > 50 && c.evicted_early > 0 && c.updates_applied > 0);
    b
}

fn bytes_of(b: &ReplayBuffer) -> Vec<u8> {
    let mut bytes = Vec::new();
    b.write_snapshot(&mut bytes).unwrap();
    bytes
}

fn restore(bytes: &[u8]) -> Result<ReplayBuffer, SnapshotError> {
    ReplayBuffer::read_snapshot(&mut &bytes[..], config(), DIMS)
}

fn assert_same(a: &ReplayBuffer, b: &ReplayBuffer) {
    assert_eq!(a.counters(), b.counters());
    assert_eq!(a.len(), b.len());
    let (ids_a, ids_b): (Vec<_>, Vec<_>) = (a.live_slots().collect(), b.live_slots().collect());
    assert_eq!(ids_a, ids_b);
    for id in ids_a {
        assert_eq!(a.get(id), b.get(id));
    }
    assert_eq!(a.tree.total().to_bits(), b.tree.total().to_bits());
    assert_eq!(a.tree.max(), b.tree.max());
}

#[test]
fn round_trip_gives_the_same_contents_priorities_counters_and_samples() {
    let mut original = used_buffer();
    let bytes = bytes_of(&original);
    let mut restored = restore(&bytes).unwrap();
    assert_same(&original, &restored);
    // Same seed, same batches, and the two stay in step afterwards.
    let (mut ra, mut rb) = (StdRng::seed_from_u64(99), StdRng::seed_from_u64(99));
    let (mut oa, mut ob) = (SampledBatch::new(), SampledBatch::new());
    for step in 0..20 {
        original.sample(16, step, &mut ra, &mut oa).unwrap();
        restored.sample(16, step, &mut rb, &mut ob).unwrap();
        assert_eq!(oa, ob);
        let errors = vec![step as f32; 16];
        original.update_priorities(&oa.slots, &oa.generations, &errors).unwrap();
        restored.update_priorities(&ob.slots, &ob.generations, &errors).unwrap();
        let batch = OwnedBatch::run(DIMS, 0, 1000 + step as u32 * 2, 2);
        assert_eq!(original.insert_batch(batch.batch()), restored.insert_batch(batch.batch()));
    }
    assert_same(&original, &restored);
    // Writing the restored buffer gives the same bytes as writing the original.
    assert_eq!(bytes_of(&original), bytes_of(&restored));
}

#[test]
fn mode_and_beta_may_change_at_restore() {
    let bytes = bytes_of(&used_buffer());
    let cfg = ReplayConfig { mode: SamplingMode::Uniform, beta_start: 0.5, ..config() };
    let restored = ReplayBuffer::read_snapshot(&mut &bytes[..], cfg, DIMS).unwrap();
    assert_eq!(restored.config().mode, SamplingMode::Uniform);
    assert_eq!(restored.beta(0), 0.5);
}

#[test]
fn an_empty_buffer_round_trips() {
    let b = ReplayBuffer::new(config(), DIMS).unwrap();
    let restored = restore(&bytes_of(&b)).unwrap();
    assert!(restored.is_empty());
    assert_eq!(restored.counters(), b.counters());
}

#[test]
fn a_filling_buffer_writes_only_what_it_holds_and_round_trips() {
    let mut b = ReplayBuffer::new(config(), DIMS).unwrap();
    let empty = bytes_of(&b).len();
    let batch = OwnedBatch::run(DIMS, 0, 0, 5).with_td(vec![1.0, 2.0, 3.0, 4.0, 5.0]);
    b.insert_batch(batch.batch()).unwrap();
    let bytes = bytes_of(&b);
    // 5 slots (priority, 3 actions, reward, flag, next row) and the 6 rows of one 5-step episode.
    let slot = 8 + 3 * 4 + 4 + 1 + 4;
    assert_eq!(bytes.len(), empty + 5 * slot + 6 * 4 * 4);
    let restored = restore(&bytes).unwrap();
    assert_same(&b, &restored);
    assert_eq!(bytes_of(&restored), bytes);
    // The wrapped buffer holds whole rings.
    let full = bytes_of(&used_buffer()).len();
    assert_eq!(full, empty + 50 * slot + 70 * 4 * 4);
}

#[test]
fn a_version_2_snapshot_with_whole_rings_is_read() {
    for original in [used_buffer(), {
        let mut b = ReplayBuffer::new(config(), DIMS).unwrap();
        b.insert_batch(OwnedBatch::run(DIMS, 1, 0, 3).batch()).unwrap();
        b
    }] {
        let mut v2 = Vec::new();
        original.write_snapshot_version(&mut v2, 2).unwrap();
        assert_eq!(v2[8..12], 2u32.to_le_bytes());
        let restored = restore(&v2).unwrap();
        assert_same(&original, &restored);
        assert_eq!(bytes_of(&restored), bytes_of(&original));
    }
}

#[test]
fn corruption_and_truncation_are_detected() {
    let bytes = bytes_of(&used_buffer());
    // Flip one bit at several places past the header: the checksum catches each.
    for at in [100, bytes.len() / 2, bytes.len() - 9, bytes.len() - 1] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        assert!(matches!(restore(&bad), Err(SnapshotError::ChecksumMismatch)), "byte {at}");
    }
    for len in [0, 5, 40, bytes.len() / 2, bytes.len() - 1] {
        let err = restore(&bytes[..len]).unwrap_err();
        assert!(
            matches!(&err, SnapshotError::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof),
            "length {len}: {err}"
        );
    }
}

#[test]
fn other_formats_versions_dims_and_settings_are_rejected() {
    let bytes = bytes_of(&used_buffer());
    let mut magic = bytes.clone();
    magic[0] = b'X';
    assert!(matches!(restore(&magic), Err(SnapshotError::BadMagic)));
    let mut version = bytes.clone();
    // Version 1, the format before the CRC-32 trailer, is refused by name, not as a bad checksum.
    version[8..12].copy_from_slice(&1u32.to_le_bytes());
    let err = restore(&version).unwrap_err();
    assert!(matches!(err, SnapshotError::UnsupportedVersion { found: 1, supported: 3 }));
    assert_eq!(err.to_string(), "snapshot format version 1 is not supported (this build reads 3)");
    let other = Dims { obs_dim: 5, act_dim: 3 };
    let other_cfg = ReplayBuffer::read_snapshot(&mut &bytes[..], config(), other).unwrap_err();
    assert_eq!(
        other_cfg.to_string(),
        "snapshot dims (obs_dim 4, act_dim 3) differ from the task's (obs_dim 5, act_dim 3)"
    );
    let read = |cfg: ReplayConfig| ReplayBuffer::read_snapshot(&mut &bytes[..], cfg, DIMS).unwrap_err();
    let err = read(ReplayConfig { capacity_transitions: 60, ..config() });
    assert_eq!(err.to_string(), "snapshot capacity_transitions is 50, the configuration says 60");
    let err = read(ReplayConfig { observation_rows: Some(71), ..config() });
    assert!(matches!(err, SnapshotError::ConfigMismatch { field: "observation_rows", .. }));
    let err = read(ReplayConfig { alpha: 0.6, ..config() });
    assert_eq!(err.to_string(), "snapshot alpha is 0.5, the configuration says 0.6");
    let err = read(ReplayConfig { epsilon: 1e-5, ..config() });
    assert!(matches!(err, SnapshotError::ConfigMismatch { field: "epsilon", .. }));
    let err = read(ReplayConfig { alpha: 2.0, ..config() });
    assert!(matches!(err, SnapshotError::Config(ConfigError::Alpha { .. })));
}

#[test]
fn a_well_formed_but_inconsistent_snapshot_is_rejected() {
    // Rewrite the tail counter (offset 12 + 7 × 8) to 0 and fix the checksum: the live range would
    // exceed the ring.
    let bytes = bytes_of(&used_buffer());
    let mut bad = bytes[..bytes.len() - 4].to_vec();
    bad[68..76].copy_from_slice(&0u64.to_le_bytes());
    bad.extend_from_slice(&crc32fast::hash(&bad).to_le_bytes());
    let err = restore(&bad).unwrap_err();
    assert_eq!(err.to_string(), "snapshot is inconsistent: live range larger than the ring");
}
