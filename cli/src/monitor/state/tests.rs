use proto::{BarrierReport, NodeId};

use super::*;
use crate::monitor::fixtures::{self, at};
use crate::monitor::record::Record;
use crate::monitor::view;
use serde_json::Value;

/// A run seen from the middle: every role reporting, executor 1 blocked, executor 2 dead.
fn busy() -> MonitorState {
    let mut s = MonitorState::new(fixtures::run());
    s.on_stats(&fixtures::learner());
    s.on_stats(&fixtures::replay());
    s.on_stats(&fixtures::executor(0, 3000.0, 100.0, false));
    s.on_stats(&fixtures::executor(1, 2500.0, 40.0, true));
    s.on_stats(&fixtures::executor(2, 1000.0, 90.0, false));
    s.on_step(&fixtures::step(5000));
    for (role, id) in [(Role::Learner, 0), (Role::Executor, 0), (Role::Executor, 1), (Role::Executor, 2)] {
        s.on_liveliness(&fixtures::liveliness(role, id), true);
    }
    s.on_liveliness(&fixtures::liveliness(Role::Executor, 2), false);
    s
}

#[test]
fn tick_sums_executors_and_takes_the_learners_figures() {
    let t = busy().tick(at(12.5));
    assert_eq!(t.learner_step, Some(5000));
    assert_eq!(t.weights_version, Some(4990));
    assert_eq!(t.updates_per_s, Some(612.5));
    assert_eq!(t.replay_size, Some(9000.0));
    assert_eq!(t.losses, Losses { q_loss: Some(0.25), v_loss: Some(0.125), policy_loss: Some(-3.5) });
    // Dead executor 2's steps count in the total, its rate does not.
    assert_eq!(t.env_steps_total, Some(6500));
    assert_eq!(t.env_steps_per_s_total, Some(140.0));
    let ids: Vec<u32> = t.executors.iter().map(|r| r.id).collect();
    assert_eq!(ids, [0, 1, 2]);
    assert_eq!(t.executors[1].blocked, Some(true));
    assert_eq!(t.executors[0].blocked, Some(false));
    assert_eq!(t.executors[2].alive, Some(false));
    assert_eq!(t.executors[0].weights_lag_steps, Some(2.0));
    assert_eq!(t.blocked.len(), 1);
    assert_eq!(t.blocked[0].node, "executor/1");
    assert_eq!(t.blocked[0].what, "executor/barrier");
}

#[test]
fn an_empty_state_ticks_all_unknowns() {
    let t = MonitorState::new(fixtures::run()).tick(at(1.0));
    assert_eq!(t.learner_step, None);
    assert_eq!(t.env_steps_total, None);
    assert_eq!(t.env_steps_per_s_total, None);
    assert!(t.executors.is_empty() && t.blocked.is_empty());
    let line = serde_json::from_str::<Value>(&Record::Tick(t.clone()).to_json()).unwrap();
    for key in ["learner_step", "updates_per_s", "replay_size", "env_steps_total", "env_steps_per_s_total"] {
        assert_eq!(line.get(key), Some(&Value::Null), "{key}");
    }
}

#[test]
fn the_learner_step_falls_back_to_the_global_step() {
    let mut s = MonitorState::new(fixtures::run());
    s.on_step(&fixtures::step(777));
    assert_eq!(s.tick(at(0.0)).learner_step, Some(777));
    s.on_stats(&fixtures::learner());
    assert_eq!(s.tick(at(0.0)).learner_step, Some(5000));
}

#[test]
fn a_newer_report_replaces_the_older_one() {
    let mut s = busy();
    s.on_stats(&fixtures::executor(1, 2600.0, 50.0, false));
    let t = s.tick(at(2.0));
    assert_eq!(t.executors[1].env_steps, Some(2600));
    assert_eq!(t.executors[1].blocked, Some(false));
    assert!(t.blocked.is_empty());
    assert_eq!(t.env_steps_per_s_total, Some(150.0));
}

#[test]
fn env_steps_are_the_newest_of_stats_barrier_and_episodes() {
    let mut s = busy();
    s.on_barrier(&fixtures::barrier_key(0), &barrier(0, 3100));
    assert_eq!(s.tick(at(1.0)).env_steps_total, Some(6600));
    let record = s.on_episode(at(1.5), &fixtures::episode(0, 3, 250.0, 3200)).unwrap();
    assert_eq!(record.env_steps_total, Some(6700));
    // An executor known only from its episodes still counts.
    let record = s.on_episode(at(1.6), &fixtures::episode(7, 0, 10.0, 1000)).unwrap();
    assert_eq!(record.env_steps_total, Some(7700));
    assert_eq!(s.tick(at(2.0)).executors.last().map(|r| (r.id, r.env_steps)), Some((7, Some(1000))));
}

fn barrier(executor_id: u32, env_steps: u64) -> Vec<u8> {
    proto::encode(&BarrierReport {
        executor_id,
        env_steps,
        allowed_env_steps: 5500,
        learner_step_seen: 5000,
        joined_at: 0,
        weights_version: 4990,
        blocked: false,
        blocked_ms_total: 0,
    })
}

#[test]
fn a_barrier_report_counts_only_on_its_own_key() {
    let mut s = busy();
    let before = s.tick(at(1.0));
    // Executor 9's report on executor 0's key, and one on a key that is no barrier key.
    s.on_barrier(&fixtures::barrier_key(0), &barrier(9, 50_000));
    s.on_barrier("elsewhere/control/barrier/9", &barrier(9, 50_000));
    let after = s.tick(at(2.0));
    assert_eq!(after.env_steps_total, before.env_steps_total);
    assert_eq!(after.executors.iter().map(|r| r.id).collect::<Vec<_>>(), [0, 1, 2], "no phantom row");
    let line = serde_json::from_str::<Value>(&Record::Tick(after.clone()).to_json()).unwrap();
    assert_eq!(line.get("undecodable").and_then(|u| u.get("barrier")).and_then(Value::as_u64), Some(2));
    // The same report on its own key counts.
    s.on_barrier(&fixtures::barrier_key(9), &barrier(9, 500));
    assert_eq!(s.tick(at(3.0)).executors.last().map(|r| (r.id, r.env_steps)), Some((9, Some(500))));
}

#[test]
fn a_restarted_executor_adds_to_its_ids_steps() {
    let mut s = busy();
    assert_eq!(s.tick(at(1.0)).env_steps_total, Some(6500));
    // Executor 2 (dead at 1000 steps) comes back as a new process counting from 0.
    s.on_liveliness(&fixtures::liveliness(Role::Executor, 2), true);
    assert_eq!(s.tick(at(2.0)).env_steps_total, Some(6500));
    s.on_stats(&fixtures::executor(2, 300.0, 90.0, false));
    let t = s.tick(at(3.0));
    assert_eq!(t.env_steps_total, Some(6800));
    assert_eq!(t.executors[2].env_steps, Some(1300));
    assert_eq!(t.executors[2].alive, Some(true));
    assert_eq!((s.returns(NodeId { role: Role::Executor, id: 2 }), s.returns_total()), (1, 1));
    // A token that blips while the process goes on (a lost link) is not a new process.
    s.on_liveliness(&fixtures::liveliness(Role::Executor, 0), false);
    s.on_liveliness(&fixtures::liveliness(Role::Executor, 0), true);
    s.on_stats(&fixtures::executor(0, 3100.0, 100.0, false));
    assert_eq!(s.tick(at(4.0)).env_steps_total, Some(6900));
}

#[test]
fn recent_return_is_the_mean_of_the_last_twenty_episodes() {
    let mut s = MonitorState::new(fixtures::run());
    assert_eq!(s.recent_return(), None);
    for i in 0..30u64 {
        s.on_episode(at(i as f64), &fixtures::episode(0, i, i as f64, (i + 1) * 1000)).unwrap();
    }
    // Episodes 10..=29: mean 19.5.
    assert_eq!(s.recent_return(), Some(RecentReturn { mean: 19.5, count: RECENT_EPISODES }));
}

#[test]
fn undecodable_messages_are_counted_per_family() {
    let mut s = busy();
    s.on_stats(b"garbage");
    let mut corrupt = fixtures::learner();
    let last = corrupt.len() - 1;
    corrupt[last] ^= 0xff;
    s.on_stats(&corrupt);
    // Right frame, wrong kind: an episode where an evaluation belongs.
    assert_eq!(s.on_eval(at(1.0), &fixtures::episode(0, 0, 1.0, 1)), None);
    s.on_liveliness("rl/ant-test/liveliness/monitor/0", true);
    s.on_liveliness("rl/other-run/liveliness/executor/0", true);
    assert_eq!(s.undecodable().get(Family::Stats), 2);
    assert_eq!(s.undecodable().get(Family::Eval), 1);
    assert_eq!(s.undecodable().get(Family::Liveliness), 2);
    assert_eq!(s.undecodable().get(Family::Episodes), 0);
    assert_eq!(s.received().get(Family::Stats), 7);
    let line = serde_json::from_str::<Value>(&Record::Tick(s.tick(at(1.0))).to_json()).unwrap();
    let undecodable = line.get("undecodable").unwrap();
    assert_eq!(undecodable.get("stats").and_then(Value::as_u64), Some(2));
    assert_eq!(undecodable.get("liveliness").and_then(Value::as_u64), Some(2));
    assert_eq!(undecodable.get("step").and_then(Value::as_u64), Some(0));
    // The good learner report survived the corrupt one.
    assert_eq!(s.tick(at(1.0)).updates_per_s, Some(612.5));
}

#[test]
fn tick_line_holds_every_figure() {
    let line = serde_json::from_str::<Value>(&Record::Tick(busy().tick(at(12.5))).to_json()).unwrap();
    assert_eq!(line.get("type").and_then(Value::as_str), Some("tick"));
    assert_eq!(line.get("unix_ms").and_then(Value::as_u64), Some(1_700_000_012_500));
    assert_eq!(line.get("elapsed_s").and_then(Value::as_f64), Some(12.5));
    assert_eq!(line.get("learner_step").and_then(Value::as_u64), Some(5000));
    assert_eq!(line.get("updates_per_s").and_then(Value::as_f64), Some(612.5));
    assert_eq!(line.get("env_steps_total").and_then(Value::as_u64), Some(6500));
    assert_eq!(line.get("env_steps_per_s_total").and_then(Value::as_f64), Some(140.0));
    let losses = line.get("losses").unwrap();
    assert_eq!(losses.get("policy_loss").and_then(Value::as_f64), Some(-3.5));
    let executors = line.get("executors").and_then(Value::as_array).unwrap();
    assert_eq!(executors.len(), 3);
    assert_eq!(executors[2].get("alive").and_then(Value::as_bool), Some(false));
    assert_eq!(executors[1].get("blocked").and_then(Value::as_bool), Some(true));
    assert_eq!(executors[1].get("env_steps").and_then(Value::as_u64), Some(2500));
    let blocked = line.get("blocked").and_then(Value::as_array).unwrap();
    assert_eq!(blocked[0].get("node").and_then(Value::as_str), Some("executor/1"));
    // The reason's quotes survive the escaping.
    assert_eq!(blocked[0].get("why").and_then(Value::as_str), Some("learner at step 5000, \"k\" = 1"));
}

#[test]
fn episode_and_eval_lines() {
    let mut s = busy();
    let episode = s.on_episode(at(3.25), &fixtures::episode(1, 4, 812.75, 2700)).unwrap();
    let line = serde_json::from_str::<Value>(&Record::Episode(episode).to_json()).unwrap();
    assert_eq!(line.get("type").and_then(Value::as_str), Some("episode"));
    assert_eq!(line.get("elapsed_s").and_then(Value::as_f64), Some(3.25));
    assert_eq!(line.get("executor_id").and_then(Value::as_u64), Some(1));
    assert_eq!(line.get("episode").and_then(Value::as_u64), Some(4));
    assert_eq!(line.get("return").and_then(Value::as_f64), Some(812.75));
    assert_eq!(line.get("length").and_then(Value::as_u64), Some(1000));
    assert_eq!(line.get("env_steps").and_then(Value::as_u64), Some(2700));
    assert_eq!(line.get("env_steps_total").and_then(Value::as_u64), Some(6700));
    assert_eq!(line.get("weights_version").and_then(Value::as_u64), Some(4990));

    let eval = s.on_eval(at(4.0), &fixtures::eval(5, 1234.5)).unwrap();
    let line = serde_json::from_str::<Value>(&Record::Eval(eval).to_json()).unwrap();
    assert_eq!(line.get("type").and_then(Value::as_str), Some("eval"));
    assert_eq!(line.get("epoch").and_then(Value::as_u64), Some(5));
    assert_eq!(line.get("learner_step").and_then(Value::as_u64), Some(5000));
    assert_eq!(line.get("mean_return").and_then(Value::as_f64), Some(1234.5));
    assert_eq!(line.get("mean_length").and_then(Value::as_f64), Some(1000.0));
    assert_eq!(line.get("mode").and_then(Value::as_str), Some("fixed_latent"));
    assert_eq!(line.get("env_steps_total").and_then(Value::as_u64), Some(6700));
    assert_eq!(s.last_eval().map(|e| e.epoch), Some(5));
}

#[test]
fn the_view_shows_stalls_rejections_and_the_dead() {
    let mut s = busy();
    s.on_stats(b"garbage");
    s.on_eval(at(4.0), &fixtures::eval(5, 1234.5)).unwrap();
    let screen = view::render(&s, &s.tick(at(12.5)));
    for expected in [
        "run ant-test",
        "up 0:12",
        "learner 5000  weights 4990  live executors 2",
        "612.5 updates/s",
        "size 9000",
        "BLOCKED",
        "DEAD",
        "executor/barrier",
        "decode/checksum",
        "epoch 5 at learner step 5000: mean return 1234.5",
        "UNDECODABLE   stats 1",
    ] {
        assert!(screen.contains(expected), "{expected:?} missing from\n{screen}");
    }
    // Zero rejection counts are not shown.
    assert!(!screen.contains("experience/stale"), "{screen}");
}
