//! The three learning-curve charts built from a [`RunRecord`]: return against env steps and against
//! wall-clock time (evaluations, and a moving average of the executors' training episodes), and the
//! learner's updates per second.

use super::chart::{Chart, Point, Rgb, Series};
use super::input::RunRecord;
use crate::monitor::state::RECENT_EPISODES;

/// A chart and the file it goes to.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotFile {
    /// File name within the output folder.
    pub file_name: &'static str,
    /// What to draw.
    pub chart: Chart,
}

/// The wall-clock axis unit, chosen so tick labels stay short.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TimeUnit {
    seconds: f64,
    name: &'static str,
}

impl TimeUnit {
    fn for_span(span_s: f64) -> TimeUnit {
        if span_s > 3.0 * 3600.0 {
            TimeUnit { seconds: 3600.0, name: "h" }
        } else if span_s > 600.0 {
            TimeUnit { seconds: 60.0, name: "min" }
        } else {
            TimeUnit { seconds: 1.0, name: "s" }
        }
    }
}

/// Every chart `sac-lsp plot` writes.
pub fn charts(record: &RunRecord) -> Vec<PlotFile> {
    let start = record.start_unix_ms.unwrap_or(0);
    let wall_s = |unix_ms: u64| unix_ms.saturating_sub(start) as f64 / 1000.0;
    let last = [
        record.episodes.last().map(|e| e.unix_ms),
        record.evals.last().map(|e| e.unix_ms),
        record.ticks.last().map(|t| t.unix_ms),
    ];
    let unit = TimeUnit::for_span(last.into_iter().flatten().map(wall_s).fold(0.0, f64::max));
    let time = |unix_ms: u64| wall_s(unix_ms) / unit.seconds;

    let averages = moving_average(record.episodes.iter().map(|e| e.episode_return), RECENT_EPISODES);
    let eval_name = "eval (deterministic)";
    let train_name = format!("episodes (avg {RECENT_EPISODES})");

    let by_steps = Chart {
        title: "return vs env steps".into(),
        x_label: "env steps (all executors)".into(),
        y_label: "return".into(),
        series: vec![
            series(
                eval_name,
                Rgb::BLUE,
                true,
                record.evals.iter().filter_map(|e| Some(Point { x: e.env_steps_total?, y: e.mean_return })),
            ),
            series(
                &train_name,
                Rgb::ORANGE,
                false,
                record
                    .episodes
                    .iter()
                    .zip(&averages)
                    .filter_map(|(e, avg)| Some(Point { x: e.env_steps_total?, y: *avg })),
            ),
        ],
    };
    let by_time = Chart {
        title: "return vs wall clock".into(),
        x_label: format!("wall clock ({})", unit.name),
        y_label: "return".into(),
        series: vec![
            series(
                eval_name,
                Rgb::BLUE,
                true,
                record.evals.iter().map(|e| Point { x: time(e.unix_ms), y: e.mean_return }),
            ),
            series(
                &train_name,
                Rgb::ORANGE,
                false,
                record.episodes.iter().zip(&averages).map(|(e, avg)| Point { x: time(e.unix_ms), y: *avg }),
            ),
        ],
    };
    let updates = Chart {
        title: "learner updates per second".into(),
        x_label: format!("wall clock ({})", unit.name),
        y_label: "updates/s".into(),
        series: vec![series(
            "learner",
            Rgb::BLUE,
            false,
            record.ticks.iter().filter_map(|t| Some(Point { x: time(t.unix_ms), y: t.updates_per_s? })),
        )],
    };
    vec![
        PlotFile { file_name: "return_vs_env_steps.png", chart: by_steps },
        PlotFile { file_name: "return_vs_wall_clock.png", chart: by_time },
        PlotFile { file_name: "updates_per_s.png", chart: updates },
    ]
}

fn series(name: &str, colour: Rgb, markers: bool, points: impl Iterator<Item = Point>) -> Series {
    Series { name: name.to_string(), colour, points: points.collect(), markers }
}

/// The trailing mean of the last `window` values at each position (fewer at the start).
pub fn moving_average(values: impl Iterator<Item = f64>, window: usize) -> Vec<f64> {
    let values: Vec<f64> = values.collect();
    let window = window.max(1);
    let mut sum = 0.0;
    let mut out = Vec::with_capacity(values.len());
    for (i, v) in values.iter().enumerate() {
        sum += v;
        if i >= window {
            sum -= values[i - window];
        }
        out.push(sum / (i + 1).min(window) as f64);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::input::{EpisodePoint, EvalPoint, TickPoint};

    #[test]
    fn moving_average_trails_over_the_window() {
        let avg = moving_average([1.0, 2.0, 3.0, 4.0, 5.0].into_iter(), 2);
        assert_eq!(avg, [1.0, 1.5, 2.5, 3.5, 4.5]);
        assert_eq!(moving_average([4.0, 8.0].into_iter(), 20), [4.0, 6.0]);
        assert!(moving_average(std::iter::empty(), 20).is_empty());
    }

    #[test]
    fn curves_use_env_steps_and_wall_clock_from_the_start() {
        let t0 = 1_700_000_000_000;
        let record = RunRecord {
            episodes: vec![
                EpisodePoint { unix_ms: t0 + 1_000, episode_return: 10.0, env_steps_total: Some(1000.0) },
                EpisodePoint { unix_ms: t0 + 2_000, episode_return: 30.0, env_steps_total: None },
            ],
            evals: vec![EvalPoint { unix_ms: t0 + 3_000, mean_return: 99.0, env_steps_total: Some(4000.0) }],
            ticks: vec![
                TickPoint { unix_ms: t0, updates_per_s: None },
                TickPoint { unix_ms: t0 + 4_000, updates_per_s: Some(600.0) },
            ],
            start_unix_ms: Some(t0),
            records: 5,
            skipped: 0,
        };
        let files = charts(&record);
        let names: Vec<&str> = files.iter().map(|f| f.file_name).collect();
        assert_eq!(names, ["return_vs_env_steps.png", "return_vs_wall_clock.png", "updates_per_s.png"]);
        let steps = &files[0].chart.series;
        assert_eq!(steps[0].points, [Point { x: 4000.0, y: 99.0 }]);
        assert!(steps[0].markers);
        // The second episode has no step count: left out here, but it still enters the average.
        assert_eq!(steps[1].points, [Point { x: 1000.0, y: 10.0 }]);
        let time = &files[1].chart.series;
        assert_eq!(time[1].points, [Point { x: 1.0, y: 10.0 }, Point { x: 2.0, y: 20.0 }]);
        assert_eq!(files[1].chart.x_label, "wall clock (s)");
        assert_eq!(files[2].chart.series[0].points, [Point { x: 4.0, y: 600.0 }]);
    }

    #[test]
    fn long_runs_are_in_minutes_or_hours() {
        assert_eq!(TimeUnit::for_span(59.0).name, "s");
        assert_eq!(TimeUnit::for_span(1800.0).name, "min");
        assert_eq!(TimeUnit::for_span(36_000.0).name, "h");
    }
}
