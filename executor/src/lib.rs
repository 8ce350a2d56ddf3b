//! An executor: steps its own environment with the current policy, computes each transition's initial
//! priority and publishes batches of transitions to the replay server.
//!
//! Skeleton: it joins the bus and announces itself (liveliness) until shut down; its issue fills in the
//! behaviour. `run` is the whole role, so the binary and the in-process test harness share it.
#![deny(missing_docs)]

mod config;

pub use config::ExecutorConfig;
use node::{Bus, Shutdown};

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
}

/// Runs the executor until `shutdown` fires.
pub async fn run(config: ExecutorConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let _alive = bus.announce().await?;
    tracing::info!(stats_interval_ms = config.stats_interval_ms, "executor up");
    shutdown.wait().await;
    bus.close().await?;
    Ok(Report { uptime_s: started.elapsed().as_secs_f64() })
}
