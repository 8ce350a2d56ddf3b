use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::*;
use crate::test_support::{Expected, OwnedBatch, obs};

const DIMS: Dims = Dims { obs_dim: 3, act_dim: 2 };

fn push_all(s: &mut Storage, b: &OwnedBatch) {
    for t in 0..b.len() {
        let e = b.transition(t);
        s.push(&Transition {
            observation: &e.observation,
            action: &e.action,
            reward: e.reward,
            next_observation: &e.next_observation,
            terminated: e.terminated,
        });
    }
}

fn stored(s: &Storage, slot: usize) -> Expected {
    Expected {
        observation: s.observation(slot).to_vec(),
        action: s.action(slot).to_vec(),
        reward: s.rewards[slot],
        next_observation: s.next_observation(slot).to_vec(),
        terminated: s.terminated[slot],
    }
}

#[test]
fn a_run_of_k_steps_takes_k_plus_one_rows() {
    let mut s = Storage::new(10, 20, DIMS);
    let run = OwnedBatch::run(DIMS, 1, 0, 6);
    push_all(&mut s, &run);
    assert_eq!((s.len(), s.rows_written), (6, 7));
    for t in 0..6 {
        assert_eq!(stored(&s, t), run.transition(t));
    }
    // The next call continuing the same episode shares its first observation too.
    push_all(&mut s, &OwnedBatch::run(DIMS, 1, 6, 2));
    assert_eq!(s.rows_written, 9);
    // Another stream starts with an observation of its own.
    push_all(&mut s, &OwnedBatch::run(DIMS, 2, 0, 1));
    assert_eq!(s.rows_written, 11);
}

#[test]
fn episode_ends_and_signed_zeros_get_their_own_rows() {
    let mut s = Storage::new(10, 20, DIMS);
    let mut b = OwnedBatch { dims: Some(DIMS), ..OwnedBatch::default() };
    b.push(obs(DIMS, 0, 0), obs(DIMS, 0, 1), 1.0);
    // Reset: the next observation of the last step is not the new episode's first observation.
    b.push(obs(DIMS, 0, 7), vec![0.0; 3], 2.0);
    b.push(vec![-0.0; 3], vec![1.0; 3], 3.0);
    push_all(&mut s, &b);
    assert_eq!(s.rows_written, 6);
    for t in 0..3 {
        assert_eq!(stored(&s, t), b.transition(t));
    }
    assert!(s.observation(2).iter().all(|v| v.is_sign_negative()));
}

#[test]
fn wrap_overwrites_the_oldest_and_bumps_generations() {
    let mut s = Storage::new(4, 16, DIMS);
    let run = OwnedBatch::run(DIMS, 0, 0, 6);
    push_all(&mut s, &run);
    assert_eq!((s.len(), s.tail, s.head, s.evicted_early), (4, 2, 6, 0));
    // Slots 0 and 1 hold transitions 4 and 5 (generation 1); 2 and 3 still 2 and 3 (generation 0).
    assert_eq!(s.occupant(0), Some(4));
    assert_eq!(s.occupant(3), Some(3));
    assert_eq!(s.generation_of(4), 1);
    assert_eq!(s.live_global(0, 0), None, "overwritten");
    assert_eq!(s.live_global(0, 1), Some(4));
    assert_eq!(s.live_global(2, 0), Some(2));
    assert_eq!(s.live_global(2, 1), None, "not written yet");
    for g in 2..6 {
        assert_eq!(stored(&s, s.slot_of(g)), run.transition(g as usize), "transition {g}");
    }
    // Slot 3 (the ring's last) is followed by slot 0 in time; its next obs is still right.
    assert_eq!(s.next_observation(3), obs(DIMS, 0, 4));
}

#[test]
fn short_of_rows_the_tail_is_evicted_early_never_corrupted() {
    // Single steps from alternating streams: two rows each, so 5 rows hold 2 transitions.
    let mut s = Storage::new(8, 5, DIMS);
    let mut all = Vec::new();
    for step in 0..9 {
        let b = OwnedBatch::run(DIMS, step % 2, step, 1);
        push_all(&mut s, &b);
        all.push(b.transition(0));
        assert!(s.len() <= 2);
        for g in s.live_globals() {
            assert_eq!(stored(&s, s.slot_of(g)), all[g as usize]);
        }
    }
    assert_eq!(s.len(), 2);
    assert_eq!(s.evicted_early, 7);
}

#[test]
fn a_row_ring_of_two_keeps_the_newest_transition() {
    let mut s = Storage::new(3, 2, DIMS);
    let run = OwnedBatch::run(DIMS, 0, 0, 5);
    push_all(&mut s, &run);
    assert_eq!((s.len(), s.tail), (1, 4));
    assert_eq!(stored(&s, s.slot_of(4)), run.transition(4));
}

/// Model check against a plain reference: random streams, run lengths, resets and ring sizes.
/// Live transitions must be exactly the newest suffix that fits both rings, and every one of them
/// must read back as inserted.
#[test]
fn random_streams_read_back_exactly() {
    let mut rng = StdRng::seed_from_u64(42);
    for case in 0..300 {
        let capacity = rng.random_range(1..12);
        let rows = rng.random_range(2..30);
        let mut s = Storage::new(capacity, rows, DIMS);
        let mut all: Vec<Expected> = Vec::new();
        // Reference: global row index of each transition's observation; rows as written.
        let mut obs_row: Vec<u64> = Vec::new();
        let mut written: Vec<Vec<f32>> = Vec::new();
        let mut steps = [0u32; 3];
        for _ in 0..rng.random_range(1..60) {
            let stream = rng.random_range(0..3);
            if rng.random_bool(0.2) {
                steps[stream] += 100; // reset: a fresh episode
            }
            let n = rng.random_range(1..6);
            let b = OwnedBatch::run(DIMS, stream as u32, steps[stream], n);
            steps[stream] += n as u32;
            for t in 0..n {
                let e = b.transition(t);
                if written.last() != Some(&e.observation) {
                    written.push(e.observation.clone());
                }
                obs_row.push(written.len() as u64 - 1);
                written.push(e.next_observation.clone());
                all.push(e);
            }
            push_all(&mut s, &b);
            let head = all.len() as u64;
            let oldest_row = (written.len() as u64).saturating_sub(rows as u64);
            let tail = (0..head)
                .find(|&g| g + capacity as u64 >= head && obs_row[g as usize] >= oldest_row)
                .unwrap_or(head);
            assert_eq!((s.tail, s.head), (tail, head), "case {case}");
            assert_eq!(s.rows_written, written.len() as u64);
            for g in s.live_globals() {
                assert_eq!(stored(&s, s.slot_of(g)), all[g as usize], "case {case}, g {g}");
                assert_eq!(s.occupant(s.slot_of(g)), Some(g));
            }
        }
    }
}

#[test]
fn bytes_for_counts_every_allocation() {
    let s = Storage::new(10, 13, DIMS);
    let allocated =
        4 * (s.rows.len() + s.actions.len() + s.rewards.len() + s.next_rows.len()) + s.terminated.len();
    assert_eq!(Storage::bytes_for(10, 13, DIMS), allocated as u128);
}
