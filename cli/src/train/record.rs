//! Per-epoch metrics: a CSV file (one row per epoch, written as it runs) and a log line.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use learner::{Evaluation, LossMeans};

use crate::tensorboard::Scalar;

/// One epoch's figures.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EpochRecord {
    /// Epoch number, from 0.
    pub epoch: u64,
    /// Env steps taken so far.
    pub env_steps: u64,
    /// Gradient updates so far.
    pub updates: u64,
    /// Seconds since the start.
    pub wall_s: f64,
    /// The evaluation after this epoch (`metrics.csv` has its mean return and length).
    pub evaluation: Evaluation,
    /// Mean return of the training episodes that ended this epoch (NaN if none did).
    pub train_return: f64,
    /// Updates per second during this epoch.
    pub updates_per_s: f64,
    /// Env steps per second during this epoch.
    pub env_steps_per_s: f64,
    /// Mean Q loss of this epoch's updates.
    pub q_loss: f64,
    /// Mean V loss.
    pub v_loss: f64,
    /// Mean policy loss.
    pub policy_loss: f64,
    /// Mean log π of the sampled actions.
    pub mean_log_prob: f64,
    /// Mean Q(s, a) of the batches.
    pub mean_q: f64,
    /// Mean temperature α of the updates (fixed unless the run tunes it).
    pub temperature: f64,
}

const HEADER: &str = "epoch,env_steps,updates,wall_s,eval_return,eval_length,train_return,updates_per_s,\
env_steps_per_s,q_loss,v_loss,policy_loss,mean_log_prob,mean_q,temperature";

/// Appends [`EpochRecord`]s to `metrics.csv`, flushing each row so the file can be watched.
#[derive(Debug)]
pub struct MetricsFile {
    out: BufWriter<File>,
}

impl MetricsFile {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path) -> Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut out = BufWriter::new(file);
        writeln!(out, "{HEADER}")?;
        out.flush()?;
        Ok(Self { out })
    }

    /// Writes one row.
    pub fn append(&mut self, r: &EpochRecord) -> Result<()> {
        writeln!(
            self.out,
            "{},{},{},{:.3},{},{},{},{:.1},{:.1},{},{},{},{},{},{}",
            r.epoch,
            r.env_steps,
            r.updates,
            r.wall_s,
            r.evaluation.mean_return,
            r.evaluation.mean_length,
            r.train_return,
            r.updates_per_s,
            r.env_steps_per_s,
            r.q_loss,
            r.v_loss,
            r.policy_loss,
            r.mean_log_prob,
            r.mean_q,
            r.temperature
        )?;
        self.out.flush()?;
        Ok(())
    }
}

impl EpochRecord {
    /// Fills the loss fields with the means of this epoch's updates (NaN when there were none).
    pub fn fill_losses(&mut self, sums: &LossMeans) {
        let means = sums.means();
        let mean = |m: f64| if sums.n == 0 { f64::NAN } else { m };
        self.q_loss = mean(means.q_loss);
        self.v_loss = mean(means.v_loss);
        self.policy_loss = mean(means.policy_loss);
        self.mean_log_prob = mean(means.mean_log_prob);
        self.mean_q = mean(means.mean_q);
        self.temperature = mean(means.temperature);
    }

    /// The TensorBoard scalars of the epoch (at its env steps), named as the monitor names the
    /// distributed run's, so the two compare in one TensorBoard.
    pub fn scalars(&self) -> Vec<Scalar> {
        vec![
            Scalar::new("eval/fixed_latent/return_mean", self.evaluation.mean_return),
            Scalar::new("eval/fixed_latent/length_mean", self.evaluation.mean_length),
            Scalar::new("train/episode_return", self.train_return),
            Scalar::new("run/updates_per_s", self.updates_per_s),
            Scalar::new("run/env_steps_per_s", self.env_steps_per_s),
            Scalar::new("run/learner_step", self.updates as f64),
            Scalar::new("learner/q_loss", self.q_loss),
            Scalar::new("learner/v_loss", self.v_loss),
            Scalar::new("learner/policy_loss", self.policy_loss),
            Scalar::new("learner/mean_log_prob", self.mean_log_prob),
            Scalar::new("learner/mean_q", self.mean_q),
            Scalar::new("learner/temperature", self.temperature),
        ]
    }
}
