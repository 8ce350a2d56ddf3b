//! Reads a monitor record (`crate::monitor::record`) into the points the curves need. Lines that do
//! not parse (a record cut off mid-line when the monitor was killed) or that are of unknown types are
//! skipped and counted, not fatal.

use std::path::Path;

use anyhow::{Context, Result};

use crate::monitor::record::Record;

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
        match Record::parse(line) {
            Ok(line) => {
                add(&mut record, &line);
                record.records += 1;
            }
            Err(_) => record.skipped += 1,
        }
    }
    record
}

/// Adds one record line.
fn add(record: &mut RunRecord, line: &Record) {
    let unix_ms = line.unix_ms();
    let total = |steps: Option<u64>| steps.map(|s| s as f64);
    match line {
        Record::Episode(e) => record.episodes.push(EpisodePoint {
            unix_ms,
            episode_return: e.episode_return,
            env_steps_total: total(e.env_steps_total),
        }),
        Record::Eval(e) => record.evals.push(EvalPoint {
            unix_ms,
            mean_return: e.eval.mean_return,
            env_steps_total: total(e.env_steps_total),
        }),
        Record::Tick(t) => record.ticks.push(TickPoint { unix_ms, updates_per_s: t.updates_per_s }),
        Record::Start(_) => {}
    }
    record.start_unix_ms = Some(record.start_unix_ms.map_or(unix_ms, |s| s.min(unix_ms)));
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
        let mut lines = vec![
            Record::Start(StartRecord { unix_ms: at(0.0).unix_ms, run_id: fixtures::RUN.into() }).to_json(),
        ];
        lines.push(Record::Tick(state.tick(at(0.5))).to_json());
        state.on_stats(&fixtures::learner());
        state.on_stats(&fixtures::executor(0, 3000.0, 100.0, false));
        let episode = state.on_episode(at(1.0), &fixtures::episode(0, 2, 321.5, 3100)).unwrap();
        lines.push(Record::Episode(episode).to_json());
        lines.push(Record::Eval(state.on_eval(at(1.5), &fixtures::eval(1, 1111.25)).unwrap()).to_json());
        lines.push(Record::Tick(state.tick(at(2.0))).to_json());
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

    #[test]
    fn records_written_before_serde_still_read() {
        // Lines of docs/results/zen-lr2e3-s1-20min-monitor.jsonl.gz (the hand-written writer's; its
        // executor rows lack policy_lag_steps and last_return).
        let text = [
            r#"{"type":"start","unix_ms":1796309907968,"run_id":"zen-lr2e3-s1"}"#,
            r#"{"type":"tick","unix_ms":1796310006971,"elapsed_s":99.002,"learner_step":21815,"weights_version":21500,"updates_per_s":232.73757372315998,"replay_size":132755,"env_steps_total":133443,"env_steps_per_s_total":1095.7073870845352,"executors":[{"id":0,"alive":true,"env_steps":16597,"env_steps_per_s":144.77787223308044,"weights_lag_steps":0,"blocked":false}],"losses":{"q_loss":2.38,"v_loss":null,"policy_loss":null},"blocked":[],"undecodable":{"stats":0,"episodes":0,"eval":0,"step":0,"barrier":0,"liveliness":0}}"#,
            r#"{"type":"episode","unix_ms":1796309957174,"elapsed_s":49.205,"executor_id":3,"episode":18,"return":240.32931323551884,"length":1000,"terminated":false,"env_steps":8927,"env_steps_total":70933,"weights_version":10000}"#,
            r#"{"type":"eval","unix_ms":1796309966682,"elapsed_s":58.713,"epoch":10,"learner_step":10000,"episodes":5,"mean_return":143.8570462792191,"std_return":164.01479984885276,"mean_length":284.8,"mode":"zero_latent","env_steps_total":81747}"#,
        ]
        .join("\n");
        let record = parse_lines(&text);
        assert_eq!((record.records, record.skipped), (4, 0));
        assert_eq!(record.ticks[0].updates_per_s, Some(232.73757372315998));
        assert_eq!(record.episodes[0].episode_return, 240.32931323551884);
        assert_eq!(record.evals[0].env_steps_total, Some(81747.0));
        // And every line reads back into the one record definition, field for field.
        for line in text.lines() {
            let parsed = Record::parse(line).unwrap();
            let again: serde_json::Value = serde_json::from_str(&parsed.to_json()).unwrap();
            let original: serde_json::Value = serde_json::from_str(line).unwrap();
            for (key, value) in original.as_object().unwrap() {
                // Integers come back as floats where the struct holds f64; rows gain the new nulls.
                let same = match (value.as_f64(), again[key].as_f64()) {
                    (Some(a), Some(b)) => a == b,
                    _ => key == "executors" || again[key] == *value,
                };
                assert!(same, "{key}: {value} became {}", again[key]);
            }
        }
    }
}
