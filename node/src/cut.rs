//! Where a deterministic run resumes ([`crate::lockstep`]): the replay server's newest cut, which
//! the learner and the executors ask it for at start (`replay/state`), so that all three continue
//! from the same checkpoint step.

use std::time::Duration;

use proto::{StatsReport, Topic};

use crate::{Bus, Shutdown};

/// The replay server's deterministic state, as its state reply gives it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cut {
    /// The checkpoint step of its newest cut (0: none; a fresh run).
    pub learner_step: u64,
    /// Whether it cuts at checkpoint steps at all (it does only with a snapshot to write).
    pub cuts: bool,
    /// Env steps each executor has delivered.
    pub progress: Vec<u64>,
}

/// How [`Cut::wait_for`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CutWait {
    /// The replay server cut its state at the step.
    Cut,
    /// It makes no cuts (it has no snapshot to write), so it never will.
    NoCuts,
    /// Not within the limit.
    TimedOut,
    /// Shut down while waiting.
    Stopped,
}

impl Cut {
    /// Reads the cut from a replay server's state reply; `None` when it does not run deterministic mode.
    pub fn from_report(report: &StatsReport) -> Option<Cut> {
        let metric = |name: &str| report.metrics.iter().find(|m| m.name == name).map(|m| m.value as u64);
        let learner_step = metric("replay/lockstep.cut")?;
        let cuts = metric("replay/lockstep.cuts") == Some(1);
        let progress = (0..).map_while(|id| metric(&format!("replay/lockstep.progress.{id}"))).collect();
        Some(Cut { learner_step, cuts, progress })
    }

    /// Waits (at most `limit`) until the replay server has cut the state at `learner_step`: the
    /// learner's last act in deterministic mode, so that a run ended at `max_updates` resumes there.
    pub async fn wait_for(
        bus: &Bus,
        learner_step: u64,
        limit: Duration,
        shutdown: Shutdown,
    ) -> anyhow::Result<CutWait> {
        let deadline = tokio::time::Instant::now() + limit;
        while tokio::time::Instant::now() < deadline {
            match Cut::ask(bus, shutdown.clone()).await? {
                Some(cut) if cut.learner_step >= learner_step => return Ok(CutWait::Cut),
                Some(cut) if !cut.cuts => return Ok(CutWait::NoCuts),
                Some(_) => tokio::time::sleep(Duration::from_millis(100)).await,
                None => return Ok(CutWait::Stopped),
            }
        }
        Ok(CutWait::TimedOut)
    }

    /// Asks the replay server, every second until it answers (or `shutdown` fires: `Ok(None)`).
    pub async fn ask(bus: &Bus, mut shutdown: Shutdown) -> anyhow::Result<Option<Cut>> {
        let mut said = false;
        loop {
            let asked = bus.query(Topic::ReplayState, None, Duration::from_secs(1)).await?;
            if let Some(Ok(payload)) = asked {
                let report: StatsReport = proto::decode(&payload.to_bytes())?;
                return match Cut::from_report(&report) {
                    Some(cut) => Ok(Some(cut)),
                    None => anyhow::bail!(
                        "the replay server does not run deterministic mode: every role must read the same run file"
                    ),
                };
            }
            if !said {
                tracing::info!("deterministic mode: asking the replay server where the run resumes");
                said = true;
            }
            tokio::select! {
                _ = shutdown.wait() => return Ok(None),
                _ = tokio::time::sleep(Duration::from_secs(1)) => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_cut_and_every_executors_progress() {
        let node = proto::NodeId { role: proto::Role::Replay, id: 0 };
        let mut report = StatsReport::new(node, 0);
        assert_eq!(Cut::from_report(&report), None, "normal mode has no cut");
        report.push_metric("replay/lockstep.cut", 500.0);
        report.push_metric("replay/lockstep.progress.0", 1250.0);
        report.push_metric("replay/lockstep.progress.1", 1250.0);
        let no_cuts = Cut { learner_step: 500, cuts: false, progress: vec![1250, 1250] };
        assert_eq!(Cut::from_report(&report), Some(no_cuts.clone()));
        report.push_metric("replay/lockstep.cuts", 1.0);
        assert_eq!(Cut::from_report(&report), Some(Cut { cuts: true, ..no_cuts }));
    }
}
