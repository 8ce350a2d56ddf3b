//! Where a deterministic run resumes (`run::lockstep`): the replay server's newest cut, which the
//! learner and the executors ask it for at start (`replay/cut`), so that all three continue from
//! the same checkpoint step.

use std::time::Duration;

use proto::{CutState, ReplayCut, Topic};

use crate::{Bus, Shutdown};

/// The replay server's deterministic state, as its `replay/cut` reply gives it.
pub type Cut = CutState;

/// How [`wait_for_cut`] ended.
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

/// Waits (at most `limit`) until the replay server has cut the state at `learner_step`: the
/// learner's last act in deterministic mode, so that a run ended at `max_updates` resumes there.
pub async fn wait_for_cut(
    bus: &Bus,
    learner_step: u64,
    limit: Duration,
    shutdown: Shutdown,
) -> anyhow::Result<CutWait> {
    let deadline = tokio::time::Instant::now() + limit;
    while tokio::time::Instant::now() < deadline {
        match ask_cut(bus, shutdown.clone()).await? {
            Some(cut) if cut.learner_step >= learner_step => return Ok(CutWait::Cut),
            Some(cut) if !cut.cuts => return Ok(CutWait::NoCuts),
            Some(_) => tokio::time::sleep(Duration::from_millis(100)).await,
            None => return Ok(CutWait::Stopped),
        }
    }
    Ok(CutWait::TimedOut)
}

/// Asks the replay server, every second until it answers (or `shutdown` fires: `Ok(None)`).
pub async fn ask_cut(bus: &Bus, mut shutdown: Shutdown) -> anyhow::Result<Option<Cut>> {
    let mut said = false;
    loop {
        let asked = bus.query(Topic::ReplayCut, None, Duration::from_secs(1)).await?;
        if let Some(Ok(payload)) = asked {
            let reply: ReplayCut = proto::decode(&payload.to_bytes())?;
            return match reply.lockstep {
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
