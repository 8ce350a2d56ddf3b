//! A flood of malformed messages against the replay server over loopback zenoh: each is counted by
//! reason, exactly, while correct batches keep landing and sampling stays exact. A binary of its
//! own: the flood fills zenoh's receive threads, which every session of a process shares, and would
//! slow the timing of other tests beside it.

mod support;

use std::collections::BTreeMap;
use std::time::Duration;

use proto::{GlobalStep, topics};
use rand::{Rng, SeedableRng, rngs::StdRng};
use support::{Server, ant_batch, assert_exact_rows, batch_of, metric, request, test_config};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_malformed_messages_leaves_it_serving_correct_batches() {
    let (server, client) = Server::start("it-flood", test_config()).await;
    let mut rng = StdRng::seed_from_u64(3);
    let good = proto::encode(&ant_batch(0, 0, 64));
    let mut expected: BTreeMap<&str, u64> = BTreeMap::new();
    let mut send_good = 0u32;
    for i in 0..3000u32 {
        let (bytes, reason) = match i % 8 {
            0 => {
                // Random bytes that cannot start with the magic.
                let len = rng.random_range(13..300);
                let mut bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
                bytes[0] = b'X';
                (bytes, "experience/bad_magic")
            }
            1 => (good[..rng.random_range(0..good.len())].to_vec(), "experience/truncated"),
            2 => {
                let step = GlobalStep {
                    learner_step: 1,
                    weights_version: 1,
                    env_steps_per_learner_step: 1,
                    warm_up_share: 0,
                    min_weights_version: 0,
                    live_executors: 1,
                };
                (proto::encode(&step), "experience/wrong_kind")
            }
            3 => {
                let mut nan = ant_batch(0, 0, 4);
                nan.transitions.observations[rng.random_range(0..4 * 105)] = f32::NAN;
                (proto::encode(&nan), "experience/non_finite")
            }
            4 => {
                let mut bytes = good.clone();
                bytes[2] = 7;
                (bytes, "experience/bad_version")
            }
            5 => {
                let mut bytes = good.clone();
                let at = rng.random_range(13..bytes.len());
                bytes[at] ^= 1 << rng.random_range(0..8);
                (bytes, "experience/checksum")
            }
            6 => {
                let mut wrong = ant_batch(0, 0, 2);
                wrong.transitions.obs_dim = 10;
                wrong.transitions.observations.truncate(20);
                wrong.transitions.next_observations.truncate(20);
                (proto::encode(&wrong), "experience/dims")
            }
            _ => {
                let first = send_good * 32;
                send_good += 1;
                client.put_batch(&ant_batch(1, first, 32)).await;
                continue;
            }
        };
        *expected.entry(reason).or_default() += 1;
        client.put_raw(0, bytes).await;
    }
    // Malformed priority updates and sample requests too.
    client.bus.session().put(topics::replay_priorities(&server.run), vec![1u8, 2, 3]).await.expect("put");
    *expected.entry("priorities/truncated").or_default() += 1;
    let bad_request = client.sample_raw(vec![b'S', b'L', 0, 0], Duration::from_secs(5)).await;
    assert!(bad_request.unwrap_err().contains("bad sample request"));
    *expected.entry("sample/truncated").or_default() += 1;

    let total: u64 = expected.values().sum();
    let inserted = send_good * 32;
    let state = client
        .wait_state("every message handled", |s| {
            metric(s, "replay/rejected_total") == total as f64
                && metric(s, "replay/inserted_transitions_total") == inserted as f64
        })
        .await;
    let rejected: BTreeMap<String, u64> =
        state.rejected.iter().map(|r| (r.reason.clone(), r.count)).collect();
    let expected: BTreeMap<String, u64> = expected.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    assert_eq!(rejected, expected);
    for id in 0..20 {
        let batch = batch_of(client.sample(request(id, 128)).await);
        assert_exact_rows(&batch, 0..inserted);
    }
    let report = server.stop().await;
    assert_eq!(report.rejected, expected);
    assert_eq!(report.counters.sampled_batches, 20);
}
