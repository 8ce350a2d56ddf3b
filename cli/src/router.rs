//! `sac-lsp router`: a zenoh router and nothing else, for the hosts of a multi-host run. Executors on
//! a host connect to its router as clients, so whatever the other hosts publish (weights, steps)
//! crosses to that host once and the router hands it to each executor there; `deploy/scale.sh`
//! measures this. It serves every run on the bus (a router carries keys, not runs). `zenohd` from
//! the zenoh project does the same job; this one needs nothing beyond the project's own build.

use anyhow::{Context, Result};
use clap::Args;
use node::{BusConfig, Shutdown, ZenohMode};

/// Options of `sac-lsp router`.
#[derive(Debug, Args)]
pub struct RouterArgs {
    /// Endpoints to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[arg(long, required = true)]
    listen: Vec<String>,
    /// Other routers (or peers) to connect to, e.g. tcp/10.0.0.1:7447 (repeatable); retried until
    /// they answer.
    #[arg(long)]
    connect: Vec<String>,
    /// A zenoh JSON5 config file (TLS, access control, ...); the flags above are applied on top.
    #[arg(long)]
    zenoh_config: Option<std::path::PathBuf>,
    /// Extra zenoh config values as KEY:JSON5.
    #[arg(long = "zenoh-cfg", value_name = "KEY:VALUE")]
    zenoh_cfg: Vec<String>,
}

/// Runs the router until SIGINT or SIGTERM.
pub fn run(args: &RouterArgs) -> Result<()> {
    let config = BusConfig {
        mode: ZenohMode::Router,
        connect: args.connect.clone(),
        listen: args.listen.clone(),
        multicast: false,
        zenoh_config: args.zenoh_config.clone(),
        overrides: args.zenoh_cfg.clone(),
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(async {
        let session = zenoh::open(config.to_zenoh()?)
            .await
            .map_err(anyhow::Error::msg)
            .context("opening the router")?;
        tracing::info!(listen = ?args.listen, connect = ?args.connect, zid = %session.zid(), "router up");
        Shutdown::on_signals().wait().await;
        session.close().await.map_err(anyhow::Error::msg)?;
        tracing::info!("router stopped");
        Ok(())
    })
}
