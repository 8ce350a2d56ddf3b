//! Encoded messages of a small run (learner, replay, param server, two executors), shared by the
//! monitor's and the plot reader's tests.

use proto::{
    BlockedReason, EpisodeReport, EvalReport, GlobalStep, NodeId, RejectCount, Role, RunId, StatsReport,
};

use super::tick::Now;

pub const RUN: &str = "ant-test";

pub fn run() -> RunId {
    RunId::new(RUN).expect("valid run id")
}

pub fn at(elapsed_s: f64) -> Now {
    Now { unix_ms: 1_700_000_000_000 + (elapsed_s * 1000.0) as u64, elapsed_s }
}

pub fn stats(role: Role, id: u32, metrics: &[(&str, f64)]) -> StatsReport {
    let mut r = StatsReport::new(NodeId { role, id }, at(0.0).unix_ms);
    for (name, value) in metrics {
        r.push_metric(*name, *value);
    }
    r
}

pub fn learner() -> Vec<u8> {
    proto::encode(&stats(
        Role::Learner,
        0,
        &[
            ("learner/learner_step", 5000.0),
            ("learner/updates_per_s", 612.5),
            ("learner/q_loss", 0.25),
            ("learner/v_loss", 0.125),
            ("learner/policy_loss", -3.5),
            ("learner/wait_fraction", 0.1),
        ],
    ))
}

pub fn replay() -> Vec<u8> {
    let mut r =
        stats(Role::Replay, 0, &[("replay/size_transitions", 9000.0), ("replay/inserts_per_s", 700.0)]);
    r.rejected.push(RejectCount { reason: "decode/checksum".into(), count: 3 });
    r.rejected.push(RejectCount { reason: "experience/stale".into(), count: 0 });
    proto::encode(&r)
}

pub fn executor(id: u32, env_steps: f64, per_s: f64, blocked: bool) -> Vec<u8> {
    let mut r = stats(
        Role::Executor,
        id,
        &[
            ("executor/env_steps", env_steps),
            ("executor/env_steps_per_s", per_s),
            ("executor/weights_lag_steps", 2.0),
            ("executor/blocked", if blocked { 1.0 } else { 0.0 }),
        ],
    );
    if blocked {
        r.blocked.push(BlockedReason {
            what: "executor/barrier".into(),
            why: "learner at step 5000, \"k\" = 1".into(),
            since_ms: at(0.0).unix_ms,
        });
    }
    proto::encode(&r)
}

pub fn step(learner_step: u64) -> Vec<u8> {
    proto::encode(&GlobalStep {
        learner_step,
        weights_version: learner_step - 10,
        env_steps_per_learner_step: 1,
        warm_up_share: 500,
        min_weights_version: 0,
        live_executors: 2,
    })
}

pub fn episode(executor_id: u32, episode: u64, episode_return: f64, env_steps: u64) -> Vec<u8> {
    proto::encode(&EpisodeReport {
        executor_id,
        episode,
        episode_return,
        length: 1000,
        terminated: false,
        env_steps,
        weights_version: 4990,
    })
}

pub fn eval(epoch: u64, mean_return: f64) -> Vec<u8> {
    proto::encode(&EvalReport {
        epoch,
        learner_step: epoch * 1000,
        episodes: 1,
        mean_return,
        mean_length: 1000.0,
        std_return: 0.0,
        mode: proto::EvalMode::FixedLatent,
        goal_success: None,
    })
}

pub fn liveliness(role: Role, id: u32) -> String {
    proto::topics::liveliness(&run(), NodeId { role, id })
}

pub fn barrier_key(executor_id: u32) -> String {
    proto::Topic::ControlBarrier { executor_id }.key(&run())
}
