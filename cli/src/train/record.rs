//! Per-epoch metrics: a CSV file (one row per epoch, written as it runs) and a log line.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

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
    /// Mean return of the deterministic evaluation episodes after this epoch.
    pub eval_return: f64,
    /// Mean length of those episodes.
    pub eval_length: f64,
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
}

const HEADER: &str = "epoch,env_steps,updates,wall_s,eval_return,eval_length,train_return,updates_per_s,\
env_steps_per_s,q_loss,v_loss,policy_loss,mean_log_prob,mean_q";

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
            "{},{},{},{:.3},{},{},{},{:.1},{:.1},{},{},{},{},{}",
            r.epoch,
            r.env_steps,
            r.updates,
            r.wall_s,
            r.eval_return,
            r.eval_length,
            r.train_return,
            r.updates_per_s,
            r.env_steps_per_s,
            r.q_loss,
            r.v_loss,
            r.policy_loss,
            r.mean_log_prob,
            r.mean_q
        )?;
        self.out.flush()?;
        Ok(())
    }
}

/// Running mean of the update metrics within an epoch.
#[derive(Debug, Default, Clone)]
pub struct LossMeans {
    count: u64,
    q_loss: f64,
    v_loss: f64,
    policy_loss: f64,
    mean_log_prob: f64,
    mean_q: f64,
}

impl LossMeans {
    /// Adds one update's metrics.
    pub fn add(&mut self, m: &agent::Metrics) {
        self.count += 1;
        self.q_loss += f64::from(m.q_loss);
        self.v_loss += f64::from(m.v_loss);
        self.policy_loss += f64::from(m.policy_loss);
        self.mean_log_prob += f64::from(m.mean_log_prob);
        self.mean_q += f64::from(m.mean_q);
    }

    /// Fills the loss fields of `record` with the means (NaN when there were no updates).
    pub fn fill(&self, record: &mut EpochRecord) {
        let n = self.count as f64;
        let mean = |sum: f64| if self.count == 0 { f64::NAN } else { sum / n };
        record.q_loss = mean(self.q_loss);
        record.v_loss = mean(self.v_loss);
        record.policy_loss = mean(self.policy_loss);
        record.mean_log_prob = mean(self.mean_log_prob);
        record.mean_q = mean(self.mean_q);
    }
}
