//! The parameter server: holds the latest weights keyed by the global step, announces each new step,
//! and enforces the executors' barrier.
//!
//! So far: the sans-IO cores ([`Barrier`]: the per-executor global-step barrier; [`ParamStore`]: the
//! latest weights). The zenoh shell is still a skeleton that joins the bus and announces itself
//! (liveliness) until shut down; its issue fills in the behaviour. `run` is the whole role, so the
//! binary and the in-process test harness share it.
#![deny(missing_docs)]

mod barrier;
mod config;
mod store;

pub use barrier::{Barrier, BarrierRule, Permit, WaitReason};
pub use store::{ParamStore, Rejected, StoreCounts};

pub use config::ParamServerConfig;
use node::{Bus, Shutdown};

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
}

/// Runs the param-server until `shutdown` fires.
pub async fn run(config: ParamServerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let _alive = bus.announce().await?;
    tracing::info!(stats_interval_ms = config.stats_interval_ms, "param-server up");
    shutdown.wait().await;
    bus.close().await?;
    Ok(Report { uptime_s: started.elapsed().as_secs_f64() })
}
