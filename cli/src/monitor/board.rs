//! What the monitor writes to TensorBoard (`runs/<run-id>/tensorboard/`): every record line as
//! scalars, at the run's total env steps (the x axis of an RL learning curve; TensorBoard's "wall"
//! and "relative" views give the time axis).
//!
//! - `eval/<mode>/return_mean`, `return_std`, `length_mean`, `learner_step` (and `goal_success`
//!   with HER): every evaluation;
//! - `train/episode_return`, `train/episode_length`: every finished executor episode;
//! - `run/...`: the tick's run-wide figures (updates/s, env steps/s, replay size, learner step);
//! - every metric of every process's latest stats under its own name (`learner/q_loss`,
//!   `learner/temperature`, `replay/...`), executors' with their id (`executor/3/weights_lag_steps`).

use std::path::Path;

use anyhow::Result;
use proto::{Role, StatsReport};

use super::record::{EpisodeRecord, EvalRecord, Record};
use super::tick::Tick;
use crate::tensorboard::{EventWriter, Scalar};

/// Milliseconds between two tick events. Every process's metrics each second would make ~7 MB per
/// 20 minutes of an 8-executor run; every 5 s is plenty for curves that span minutes.
const TICK_EVERY_MS: u64 = 5_000;

/// The monitor's event file.
#[derive(Debug)]
pub struct Board {
    writer: EventWriter,
    last_tick_ms: Option<u64>,
}

impl Board {
    /// A new event file in `dir`.
    pub fn create(dir: &Path, unix_ms: u64) -> Result<Board> {
        Ok(Board { writer: EventWriter::create(dir, seconds(unix_ms))?, last_tick_ms: None })
    }

    /// Writes `record`'s scalars; a tick also writes `reports` (the processes' latest stats), at
    /// most every [`TICK_EVERY_MS`].
    pub fn on_record(&mut self, record: &Record, reports: &[&StatsReport]) -> Result<()> {
        let (step, scalars) = match record {
            Record::Start(_) => return Ok(()),
            Record::Tick(tick) => {
                let now = tick.now.unix_ms;
                let due = self.last_tick_ms.is_none_or(|last| now >= last + TICK_EVERY_MS);
                if !due || tick.env_steps_total.is_none() {
                    return Ok(());
                }
                self.last_tick_ms = Some(now);
                (tick.env_steps_total, tick_scalars(tick, reports))
            }
            Record::Episode(episode) => {
                (Some(episode.env_steps_total.unwrap_or(episode.env_steps)), episode_scalars(episode))
            }
            Record::Eval(eval) => (eval.env_steps_total, eval_scalars(eval)),
        };
        // Before any executor has reported there is no x to put a point at; nothing is lost, as
        // nothing has been learned yet.
        let Some(step) = step else { return Ok(()) };
        self.writer.write(seconds(record.unix_ms()), step, &scalars)
    }

    /// Writes out the buffered events.
    pub fn flush(&mut self) -> Result<()> {
        self.writer.flush()
    }

    /// The event file.
    pub fn path(&self) -> &Path {
        self.writer.path()
    }
}

fn seconds(unix_ms: u64) -> f64 {
    unix_ms as f64 / 1000.0
}

/// The tick's run-wide figures and every reported metric.
pub fn tick_scalars(tick: &Tick, reports: &[&StatsReport]) -> Vec<Scalar> {
    let run = [
        ("run/updates_per_s", tick.updates_per_s),
        ("run/env_steps_per_s", tick.env_steps_per_s_total),
        ("run/replay_size", tick.replay_size),
        ("run/learner_step", tick.learner_step.map(|s| s as f64)),
    ];
    let mut scalars: Vec<Scalar> =
        run.into_iter().filter_map(|(tag, value)| value.map(|v| Scalar::new(tag, v))).collect();
    for report in reports {
        for metric in &report.metrics {
            scalars.push(Scalar::new(metric_tag(report.role, report.id, &metric.name), metric.value));
        }
    }
    scalars
}

/// A metric's tag: its name, with the process id after the role for the role that has many.
fn metric_tag(role: Role, id: u32, name: &str) -> String {
    match (role, name.split_once('/')) {
        (Role::Executor, Some((prefix, rest))) => format!("{prefix}/{id}/{rest}"),
        (Role::Executor, None) => format!("executor/{id}/{name}"),
        _ => name.to_string(),
    }
}

/// A finished executor episode.
pub fn episode_scalars(episode: &EpisodeRecord) -> Vec<Scalar> {
    vec![
        Scalar::new("train/episode_return", episode.episode_return),
        Scalar::new("train/episode_length", f64::from(episode.length)),
    ]
}

/// An evaluation, under its mode (the run can evaluate in several).
pub fn eval_scalars(record: &EvalRecord) -> Vec<Scalar> {
    let eval = &record.eval;
    let mode = eval.mode.name();
    let mut scalars = vec![
        Scalar::new(format!("eval/{mode}/return_mean"), eval.mean_return),
        Scalar::new(format!("eval/{mode}/return_std"), eval.std_return),
        Scalar::new(format!("eval/{mode}/length_mean"), eval.mean_length),
        Scalar::new(format!("eval/{mode}/learner_step"), eval.learner_step as f64),
    ];
    scalars.extend(eval.goal_success.map(|s| Scalar::new(format!("eval/{mode}/goal_success"), s)));
    scalars
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::monitor::fixtures::{self, at};
    use crate::monitor::record::StartRecord;
    use crate::monitor::state::MonitorState;
    use crate::tensorboard::read;

    #[test]
    fn records_become_scalars_at_the_runs_env_steps() {
        let dir = tempfile::tempdir().unwrap();
        let mut board = Board::create(dir.path(), at(0.0).unix_ms).unwrap();
        let mut state = MonitorState::new(fixtures::run());
        let mut write = |record: Record, state: &MonitorState| {
            board.on_record(&record, &state.reports_sorted()).unwrap();
        };
        write(Record::Start(StartRecord { unix_ms: at(0.0).unix_ms, run_id: fixtures::RUN.into() }), &state);
        // No executor has reported: no x for a point yet.
        write(Record::Tick(state.tick(at(0.5))), &state);
        for report in [fixtures::learner(), fixtures::executor(0, 3000.0, 100.0, false)] {
            state.on_stats(&report);
        }
        state.on_stats(&fixtures::executor(3, 1000.0, 50.0, true));
        write(Record::Tick(state.tick(at(6.0))), &state);
        // Within TICK_EVERY_MS of the last tick event: skipped.
        write(Record::Tick(state.tick(at(7.0))), &state);
        let episode = state.on_episode(at(7.5), &fixtures::episode(0, 2, 321.5, 3100)).unwrap();
        write(Record::Episode(episode), &state);
        let eval = state.on_eval(at(8.0), &fixtures::eval(1, 1111.25)).unwrap();
        write(Record::Eval(eval), &state);
        write(Record::Tick(state.tick(at(11.5))), &state);
        board.flush().unwrap();

        let events = read::events(board.path());
        assert_eq!(events[0].file_version.as_deref(), Some("brain.Event:2"));
        let steps: Vec<u64> = events[1..].iter().map(|e| e.step).collect();
        assert_eq!(steps, [4000, 4100, 4100, 4100], "tick, episode, eval, tick at the env steps total");
        assert_eq!(events[1].wall_time_s, at(6.0).unix_ms as f64 / 1000.0);
        let tick: HashMap<&str, f32> = events[1].scalars.iter().map(|(t, v)| (t.as_str(), *v)).collect();
        assert_eq!(tick["run/updates_per_s"], 612.5);
        assert_eq!(tick["run/env_steps_per_s"], 150.0);
        assert_eq!(tick["learner/q_loss"], 0.25);
        assert_eq!(tick["executor/0/env_steps"], 3000.0);
        assert_eq!(tick["executor/3/weights_lag_steps"], 2.0);
        assert!(!tick.contains_key("executor/env_steps"), "executor metrics carry their id");
        assert_eq!(
            events[2].scalars,
            [("train/episode_return".to_string(), 321.5), ("train/episode_length".to_string(), 1000.0)]
        );
        let eval: HashMap<&str, f32> = events[3].scalars.iter().map(|(t, v)| (t.as_str(), *v)).collect();
        assert_eq!(eval["eval/fixed_latent/return_mean"], 1111.25);
        assert!(!eval.contains_key("eval/fixed_latent/goal_success"), "no goals, no success rate");
    }

    #[test]
    fn a_her_evaluation_writes_its_goal_success() {
        let mut state = MonitorState::new(fixtures::run());
        let mut report: proto::EvalReport = proto::decode(&fixtures::eval(2, 50.0)).unwrap();
        report.goal_success = Some(0.75);
        let record = state.on_eval(at(1.0), &proto::encode(&report)).unwrap();
        let scalars = eval_scalars(&record);
        assert!(scalars.iter().any(|s| s.tag == "eval/fixed_latent/goal_success" && s.value == 0.75));
    }
}
