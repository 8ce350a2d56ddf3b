//! The replay server: owns the prioritized replay buffer and serves it over zenoh (executors insert,
//! the learner samples and updates priorities).
//!
//! Skeleton: it joins the bus and announces itself (liveliness) until shut down; its issue fills in the
//! behaviour. `run` is the whole role, so the binary and the in-process test harness share it.
#![deny(missing_docs)]

mod config;

pub use config::ReplayServerConfig;
use node::{Bus, Shutdown};

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
}

/// Runs the replay-server until `shutdown` fires.
pub async fn run(config: ReplayServerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let _alive = bus.announce().await?;
    tracing::info!(stats_interval_ms = config.stats_interval_ms, "replay-server up");
    shutdown.wait().await;
    bus.close().await?;
    Ok(Report { uptime_s: started.elapsed().as_secs_f64() })
}
