//! The monitor's record format: one JSON object per line (JSONL), each with a `"type"`:
//!
//! - `start`: the monitor (re)started; `unix_ms`, `run_id`. Appending sessions to one file is safe
//!   because every line also carries `unix_ms`.
//! - `tick`: every interval, the [`Tick`] summary (with the undecodable-message counts per family).
//! - `episode`: every finished executor episode, as it arrives.
//! - `eval`: every learner evaluation, as it arrives.
//!
//! `elapsed_s` counts from the monitor's start; figures nobody has reported are `null` (and a field
//! an older monitor did not write reads as `null`). [`Record`] is the one definition: the monitor
//! writes it and `sac-lsp plot` reads it back (`crate::plot::input`).

use proto::{EpisodeReport, EvalReport};
use serde::{Deserialize, Serialize};

use super::tick::{Now, Tick};

/// One line of the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Record {
    /// The monitor (re)started.
    Start(StartRecord),
    /// One interval's summary.
    Tick(Tick),
    /// A finished executor episode.
    Episode(EpisodeRecord),
    /// A learner evaluation.
    Eval(EvalRecord),
}

impl Record {
    /// The JSON line (no newline).
    pub fn to_json(&self) -> String {
        // Every field is a number, string, bool, list or string-keyed map: this cannot fail.
        serde_json::to_string(self).expect("a record serializes")
    }

    /// Parses one line.
    pub fn parse(line: &str) -> serde_json::Result<Record> {
        serde_json::from_str(line)
    }

    /// When it was written, Unix milliseconds.
    pub fn unix_ms(&self) -> u64 {
        match self {
            Record::Start(r) => r.unix_ms,
            Record::Tick(r) => r.now.unix_ms,
            Record::Episode(r) => r.now.unix_ms,
            Record::Eval(r) => r.now.unix_ms,
        }
    }
}

/// The first line of a monitor session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartRecord {
    /// When the monitor started, Unix milliseconds.
    pub unix_ms: u64,
    /// The run watched.
    pub run_id: String,
}

/// One finished episode, with the run's total env steps when it arrived (the learning curve's x).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRecord {
    /// When it arrived.
    #[serde(flatten)]
    pub now: Now,
    /// The executor that ran it.
    pub executor_id: u32,
    /// Its episode counter.
    pub episode: u64,
    /// Undiscounted return.
    #[serde(rename = "return")]
    pub episode_return: f64,
    /// Steps.
    pub length: u32,
    /// Ended by termination (a fall), not by the time limit.
    pub terminated: bool,
    /// The executor's cumulative env steps at its end.
    pub env_steps: u64,
    /// Sum over executors of their newest known env steps, this episode included.
    pub env_steps_total: Option<u64>,
    /// The weights it acted with.
    pub weights_version: u64,
}

impl EpisodeRecord {
    /// The line for `episode`, arrived at `now`.
    pub fn new(now: Now, episode: &EpisodeReport, env_steps_total: Option<u64>) -> Self {
        Self {
            now,
            executor_id: episode.executor_id,
            episode: episode.episode,
            episode_return: episode.episode_return,
            length: episode.length,
            terminated: episode.terminated,
            env_steps: episode.env_steps,
            env_steps_total,
            weights_version: episode.weights_version,
        }
    }
}

/// One learner evaluation: the [`EvalReport`]'s fields as they are named on the bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalRecord {
    /// When it arrived.
    #[serde(flatten)]
    pub now: Now,
    /// The report.
    #[serde(flatten)]
    pub eval: EvalReport,
    /// Sum over executors of their newest known env steps when it arrived.
    pub env_steps_total: Option<u64>,
}
