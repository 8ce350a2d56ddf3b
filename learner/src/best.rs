//! The best policy so far: `<checkpoint dir>/best-policy.safetensors`, the weights snapshot whose
//! learner evaluation scored the highest mean return, and `best-policy.toml`, that evaluation.
//!
//! A run's newest checkpoint is not its best policy: in the 60-minute Ant runs of
//! `docs/results/issue28-tries/` the evaluations peaked between minutes 16 and 40 and then fell.
//! Keeping the best-scoring weights as they are evaluated costs one file write per new best and
//! nothing else (the evaluation thread already holds them). The score is the learner's own
//! evaluation (`eval_episodes` episodes, often 5), so the best of many noisy scores reads high:
//! re-evaluate the file on more episodes (`sac-lsp eval`, `tests/reference/eval_policy.py`) before
//! quoting it.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use agent::ParamSnapshot;
use proto::EvalReport;

const WEIGHTS: &str = "best-policy.safetensors";
const SCORE: &str = "best-policy.toml";

/// The best-policy files of one checkpoint directory.
#[derive(Debug)]
pub struct BestPolicy {
    weights: PathBuf,
    score: PathBuf,
    best: Option<EvalReport>,
}

impl BestPolicy {
    /// The files in `dir`; a run resuming there starts from the evaluation `best-policy.toml`
    /// records (an unreadable one is ignored with a warning: the next evaluation replaces it).
    pub fn open(dir: &Path) -> Self {
        let (weights, score) = (dir.join(WEIGHTS), dir.join(SCORE));
        let best = match fs::read_to_string(&score) {
            Ok(text) => toml::from_str::<EvalReport>(&text)
                .map_err(|error| tracing::warn!(path = %score.display(), %error, "best-policy score unreadable; ignored"))
                .ok(),
            Err(_) => None,
        };
        Self { weights, score, best }
    }

    /// The evaluation of the weights on disk, if any.
    pub fn best(&self) -> Option<&EvalReport> {
        self.best.as_ref()
    }

    /// Whether an evaluation `report` beats the best so far: a finite mean return above it in the
    /// same mode (one in another mode, after a resume with another `eval_mode`, starts afresh).
    pub fn beats(&self, report: &EvalReport) -> bool {
        report.mean_return.is_finite()
            && self
                .best
                .as_ref()
                .is_none_or(|best| best.mode != report.mode || report.mean_return > best.mean_return)
    }

    /// Keeps `snapshot` if `report`, its evaluation, [`beats`](Self::beats) the best so far; returns
    /// whether it did. Each file is written atomically, the weights first, so a crash between the
    /// two leaves weights at least as good as the score says.
    pub fn offer(&mut self, report: &EvalReport, snapshot: &ParamSnapshot) -> io::Result<bool> {
        if !self.beats(report) {
            return Ok(false);
        }
        let score = toml::to_string(report).map_err(io::Error::other)?;
        node::durable::write(&self.weights, &snapshot.safetensors)?;
        node::durable::write(&self.score, score.as_bytes())?;
        self.best = Some(*report);
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proto::EvalMode;

    fn report(learner_step: u64, mean_return: f64, mode: EvalMode) -> EvalReport {
        EvalReport {
            epoch: learner_step / 1000,
            learner_step,
            episodes: 5,
            mean_return,
            mean_length: 1000.0,
            std_return: 10.0,
            mode,
            goal_success: None,
        }
    }

    fn snapshot(version: u64) -> ParamSnapshot {
        ParamSnapshot { version, safetensors: version.to_le_bytes().to_vec() }
    }

    #[test]
    fn keeps_the_highest_scoring_weights_across_a_resume() {
        let dir = std::env::temp_dir().join(format!("best-policy-test-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let zero = EvalMode::ZeroLatent;
        let mut best = BestPolicy::open(&dir);
        assert!(best.best().is_none());
        assert!(best.offer(&report(1000, 100.0, zero), &snapshot(1000)).unwrap());
        assert!(!best.offer(&report(2000, 50.0, zero), &snapshot(2000)).unwrap(), "worse");
        assert!(!best.offer(&report(2500, f64::NAN, zero), &snapshot(2500)).unwrap(), "not finite");
        assert!(best.offer(&report(3000, 200.0, zero), &snapshot(3000)).unwrap());
        assert!(!best.offer(&report(4000, 200.0, zero), &snapshot(4000)).unwrap(), "a tie keeps the older");
        assert_eq!(fs::read(dir.join(WEIGHTS)).unwrap(), 3000u64.to_le_bytes());

        let mut resumed = BestPolicy::open(&dir);
        assert_eq!(resumed.best(), Some(&report(3000, 200.0, zero)));
        assert!(!resumed.offer(&report(5000, 150.0, zero), &snapshot(5000)).unwrap());
        assert!(
            resumed.offer(&report(6000, 20.0, EvalMode::FixedLatent), &snapshot(6000)).unwrap(),
            "other mode"
        );
        assert_eq!(fs::read(dir.join(WEIGHTS)).unwrap(), 6000u64.to_le_bytes());

        fs::write(dir.join(SCORE), "not toml [").unwrap();
        assert!(BestPolicy::open(&dir).best().is_none(), "unreadable score ignored");
        fs::remove_dir_all(&dir).unwrap();
    }
}
