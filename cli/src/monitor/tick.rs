//! What the monitor computes every interval: the figures of the live view's first lines and of one
//! `"tick"` record line. Plain data; [`super::state::MonitorState::tick`] fills it in.

use serde::{Deserialize, Serialize};

use super::family::FamilyCounts;

/// The time an event or tick happened, as the monitor saw it. Passed in, so the state is sans-IO.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Now {
    /// Wall clock, Unix milliseconds.
    pub unix_ms: u64,
    /// Seconds since the monitor started.
    pub elapsed_s: f64,
}

/// One interval's summary of the run. Every figure is `None` until some process has reported it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tick {
    /// When.
    #[serde(flatten)]
    pub now: Now,
    /// The learner's gradient steps (its own report first, else the param server's global step).
    pub learner_step: Option<u64>,
    /// Newest weights version the param server announced.
    pub weights_version: Option<u64>,
    /// Learner updates per second.
    pub updates_per_s: Option<f64>,
    /// Transitions in the replay buffer.
    pub replay_size: Option<f64>,
    /// Sum over executors of their newest known cumulative env steps (dead ones included: their
    /// steps were taken).
    pub env_steps_total: Option<u64>,
    /// Sum of the env steps/s of executors not known to be dead.
    pub env_steps_per_s_total: Option<f64>,
    /// One row per executor seen on any topic, by id.
    pub executors: Vec<ExecutorRow>,
    /// The learner's latest mean losses.
    pub losses: Losses,
    /// Every `blocked` entry of every process's latest report.
    pub blocked: Vec<BlockedEntry>,
    /// Messages that did not decode since the monitor started, per family.
    pub undecodable: FamilyCounts,
}

/// One executor as the monitor knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExecutorRow {
    /// Executor id.
    pub id: u32,
    /// From its liveliness token: `Some(false)` once it vanished, `None` if never seen.
    pub alive: Option<bool>,
    /// Cumulative env steps (the newest of its stats, barrier and episode reports).
    pub env_steps: Option<u64>,
    /// Env steps per second.
    pub env_steps_per_s: Option<f64>,
    /// Weight versions behind the newest published.
    pub weights_lag_steps: Option<f64>,
    /// Learner steps behind the learner.
    pub policy_lag_steps: Option<f64>,
    /// Waiting (at the barrier or for weights) right now.
    pub blocked: Option<bool>,
    /// Return of its last finished episode.
    pub last_return: Option<f64>,
}

/// The learner's loss figures.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Losses {
    /// `learner/q_loss`.
    pub q_loss: Option<f64>,
    /// `learner/v_loss`.
    pub v_loss: Option<f64>,
    /// `learner/policy_loss`.
    pub policy_loss: Option<f64>,
}

/// Something a process said it is waiting on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockedEntry {
    /// `<role>/<id>` of the reporting process.
    pub node: String,
    /// What waits.
    pub what: String,
    /// Why.
    pub why: String,
    /// Since when, Unix milliseconds.
    pub since_ms: u64,
}
