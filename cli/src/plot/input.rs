//! Reads a monitor record (`crate::monitor::record`) into the points the curves need. Lines that do
//! not parse (a record cut off mid-line when the monitor was killed) or that are of unknown types are
//! skipped and counted, not fatal.

use std::path::Path;

use anyhow::{Context, Result};

use crate::json::{self, Value};

/// A finished executor episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpisodePoint {
    /// When the monitor saw it.
    pub unix_ms: u64,
    /// Its return.
    pub episode_return: f64,
    /// The run's total env steps then, if known.
    pub env_steps_total: Option<f64>,
}

/// A learner evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalPoint {
    /// When the monitor saw it.
    pub unix_ms: u64,
    /// Mean return of the evaluation episodes.
    pub mean_return: f64,
    /// The run's total env steps then, if known.
    pub env_steps_total: Option<f64>,
}

/// One tick's learner throughput.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickPoint {
    /// When.
    pub unix_ms: u64,
    /// Learner updates per second, if reported.
    pub updates_per_s: Option<f64>,
}

/// Everything plotted from one record file, in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunRecord {
    /// Episode lines.
    pub episodes: Vec<EpisodePoint>,
    /// Eval lines.
    pub evals: Vec<EvalPoint>,
    /// Tick lines.
    pub ticks: Vec<TickPoint>,
    /// The earliest `unix_ms` of any line: wall-clock zero.
    pub start_unix_ms: Option<u64>,
    /// Lines read as records (any type, `start` included).
    pub records: usize,
    /// Lines that were not records of a known type.
    pub skipped: usize,
}

/// Reads the record at `path`.
pub fn read(path: &Path) -> Result<RunRecord> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(parse_lines(&text))
}

/// Parses record text, one JSON object per line.
pub fn parse_lines(text: &str) -> RunRecord {
    let mut record = RunRecord::default();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        match json::parse(line).ok().and_then(|v| add(&mut record, &v)) {
            Some(()) => record.records += 1,
            None => record.skipped += 1,
        }
    }
    record
}

/// Adds one parsed line; `None` if it is not a record this reader knows.
fn add(record: &mut RunRecord, line: &Value) -> Option<()> {
    let unix_ms = line.get("unix_ms")?.as_u64()?;
    let number = |key: &str| line.get(key).and_then(Value::as_f64);
    match line.get("type")?.as_str()? {
        "episode" => record.episodes.push(EpisodePoint {
            unix_ms,
            episode_return: number("return")?,
            env_steps_total: number("env_steps_total"),
        }),
        "eval" => record.evals.push(EvalPoint {
            unix_ms,
            mean_return: number("mean_return")?,
            env_steps_total: number("env_steps_total"),
        }),
        "tick" => record.ticks.push(TickPoint { unix_ms, updates_per_s: number("updates_per_s") }),
        "start" => {}
        _ => return None,
    }
    record.start_unix_ms = Some(record.start_unix_ms.map_or(unix_ms, |s| s.min(unix_ms)));
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::fixtures::{self, at};
    use crate::monitor::record::StartRecord;
    use crate::monitor::state::MonitorState;

    #[test]
    fn reads_back_what_the_monitor_writes() {
        let mut state = MonitorState::new(fixtures::run());
        let mut lines =
            vec![StartRecord { unix_ms: at(0.0).unix_ms, run_id: fixtures::RUN.into() }.to_json()];
        lines.push(state.tick(at(0.5)).to_json());
        state.on_stats(&fixtures::learner());
        state.on_stats(&fixtures::executor(0, 3000.0, 100.0, false));
        let episode = state.on_episode(at(1.0), &fixtures::episode(0, 2, 321.5, 3100)).unwrap();
        lines.push(episode.to_json());
        lines.push(state.on_eval(at(1.5), &fixtures::eval(1, 1111.25)).unwrap().to_json());
        lines.push(state.tick(at(2.0)).to_json());
        // A line cut off mid-write, and a record type from a future monitor.
        lines.push("{\"type\":\"tick\",\"unix_ms\":17".into());
        lines.push("{\"type\":\"future\",\"unix_ms\":1}".into());
        let record = parse_lines(&(lines.join("\n") + "\n"));

        assert_eq!(record.records, 5);
        assert_eq!(record.skipped, 2);
        assert_eq!(record.start_unix_ms, Some(at(0.0).unix_ms));
        assert_eq!(
            record.episodes,
            [EpisodePoint { unix_ms: at(1.0).unix_ms, episode_return: 321.5, env_steps_total: Some(3100.0) }]
        );
        assert_eq!(
            record.evals,
            [EvalPoint { unix_ms: at(1.5).unix_ms, mean_return: 1111.25, env_steps_total: Some(3100.0) }]
        );
        assert_eq!(
            record.ticks,
            [
                TickPoint { unix_ms: at(0.5).unix_ms, updates_per_s: None },
                TickPoint { unix_ms: at(2.0).unix_ms, updates_per_s: Some(612.5) },
            ]
        );
    }
}
