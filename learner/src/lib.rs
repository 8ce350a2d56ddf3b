//! The learner: pulls prioritized batches from the replay server, trains SAC-LSP, sends back priorities
//! and publishes weights through the parameter server.
//!
//! Skeleton: it joins the bus and announces itself (liveliness) until shut down; its issue fills in the
//! behaviour. `run` is the whole role, so the binary and the in-process test harness share it.
#![deny(missing_docs)]

mod config;

pub use config::LearnerConfig;
use node::{Bus, Shutdown};

/// What the role did, returned when it stops.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Report {
    /// Seconds between start and shutdown.
    pub uptime_s: f64,
}

/// Runs the learner until `shutdown` fires.
pub async fn run(config: LearnerConfig, bus: Bus, mut shutdown: Shutdown) -> anyhow::Result<Report> {
    let started = std::time::Instant::now();
    let _alive = bus.announce().await?;
    tracing::info!(stats_interval_ms = config.stats_interval_ms, "learner up");
    shutdown.wait().await;
    bus.close().await?;
    Ok(Report { uptime_s: started.elapsed().as_secs_f64() })
}
