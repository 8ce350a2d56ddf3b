//! The monitor's record format: one JSON object per line (JSONL), each with a `"type"`:
//!
//! - `start`: the monitor (re)started; `unix_ms`, `run_id`. Appending sessions to one file is safe
//!   because every line also carries `unix_ms`.
//! - `tick`: every interval, the [`Tick`] summary (with the undecodable-message counts per family).
//! - `episode`: every finished executor episode, as it arrives.
//! - `eval`: every learner evaluation, as it arrives.
//!
//! `elapsed_s` counts from the monitor's start; figures nobody has reported are `null`.
//! `sac-lsp plot` reads these lines back (`crate::plot::input`).

use proto::{EpisodeReport, EvalReport};

use super::family::Family;
use super::tick::{Now, Tick};
use crate::json::{Object, Value};

/// The first line of a monitor session.
#[derive(Debug, Clone, PartialEq)]
pub struct StartRecord {
    /// When the monitor started, Unix milliseconds.
    pub unix_ms: u64,
    /// The run watched.
    pub run_id: String,
}

impl StartRecord {
    /// The JSON line (no newline).
    pub fn to_json(&self) -> String {
        Object::new()
            .with("type", "start")
            .with("unix_ms", self.unix_ms)
            .with("run_id", self.run_id.as_str())
            .to_string()
    }
}

/// One finished episode, with the run's total env steps when it arrived (the learning curve's x).
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRecord {
    /// When it arrived.
    pub now: Now,
    /// The report.
    pub episode: EpisodeReport,
    /// Sum over executors of their newest known env steps, this episode included.
    pub env_steps_total: Option<u64>,
}

impl EpisodeRecord {
    /// The JSON line (no newline).
    pub fn to_json(&self) -> String {
        let e = &self.episode;
        timed("episode", self.now)
            .with("executor_id", e.executor_id)
            .with("episode", e.episode)
            .with("return", e.episode_return)
            .with("length", e.length)
            .with("terminated", e.terminated)
            .with("env_steps", e.env_steps)
            .with("env_steps_total", self.env_steps_total)
            .with("weights_version", e.weights_version)
            .to_string()
    }
}

/// One learner evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalRecord {
    /// When it arrived.
    pub now: Now,
    /// The report.
    pub eval: EvalReport,
    /// Sum over executors of their newest known env steps when it arrived.
    pub env_steps_total: Option<u64>,
}

impl EvalRecord {
    /// The JSON line (no newline).
    pub fn to_json(&self) -> String {
        let e = &self.eval;
        timed("eval", self.now)
            .with("epoch", e.epoch)
            .with("learner_step", e.learner_step)
            .with("episodes", e.episodes)
            .with("mean_return", e.mean_return)
            .with("std_return", e.std_return)
            .with("mean_length", e.mean_length)
            .with("mode", e.mode.name())
            .with("env_steps_total", self.env_steps_total)
            .to_string()
    }
}

impl Tick {
    /// The JSON line (no newline).
    pub fn to_json(&self) -> String {
        let executors: Vec<Value> = self
            .executors
            .iter()
            .map(|row| {
                Object::new()
                    .with("id", row.id)
                    .with("alive", row.alive)
                    .with("env_steps", row.env_steps)
                    .with("env_steps_per_s", row.env_steps_per_s)
                    .with("weights_lag_steps", row.weights_lag_steps)
                    .with("blocked", row.blocked)
                    .into()
            })
            .collect();
        let blocked: Vec<Value> = self
            .blocked
            .iter()
            .map(|b| {
                Object::new()
                    .with("node", b.node.as_str())
                    .with("what", b.what.as_str())
                    .with("why", b.why.as_str())
                    .with("since_ms", b.since_ms)
                    .into()
            })
            .collect();
        let losses = Object::new()
            .with("q_loss", self.losses.q_loss)
            .with("v_loss", self.losses.v_loss)
            .with("policy_loss", self.losses.policy_loss);
        let undecodable = Family::ALL.iter().fold(Object::new(), |object, family| {
            object.with(family.as_str(), self.undecodable.get(*family))
        });
        timed("tick", self.now)
            .with("learner_step", self.learner_step)
            .with("weights_version", self.weights_version)
            .with("updates_per_s", self.updates_per_s)
            .with("replay_size", self.replay_size)
            .with("env_steps_total", self.env_steps_total)
            .with("env_steps_per_s_total", self.env_steps_per_s_total)
            .with("executors", executors)
            .with("losses", losses)
            .with("blocked", blocked)
            .with("undecodable", undecodable)
            .to_string()
    }
}

/// An object starting with the fields every line has.
fn timed(kind: &str, now: Now) -> Object {
    Object::new().with("type", kind).with("unix_ms", now.unix_ms).with("elapsed_s", now.elapsed_s)
}
