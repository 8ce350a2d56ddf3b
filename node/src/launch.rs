//! The `main` of every role binary, written once.

use std::fmt::Debug;
use std::future::Future;

use anyhow::Context;
use proto::{NodeId, Role, RunId};
use tracing::Instrument;

use run::RoleConfig;

use crate::{Bus, BusConfig, NodeArgs, Shutdown, telemetry};

/// Sets up tracing, loads and validates the role's config table, opens the bus, and runs the role until
/// SIGINT/SIGTERM; returns the role's error, if any, for `main` to print and exit non-zero.
pub async fn launch<C, F, Fut, R>(role: Role, args: &NodeArgs, run: F) -> anyhow::Result<R>
where
    C: RoleConfig,
    F: FnOnce(C, Bus, Shutdown) -> Fut,
    Fut: Future<Output = anyhow::Result<R>>,
    R: Debug,
{
    telemetry::init();
    let config = C::load(args.config.as_deref())?;
    let run_id = RunId::new(args.run_id.clone())?;
    let node = NodeId { role, id: args.id };
    let bus = Bus::open(run_id, node, &BusConfig::from(args))
        .await
        .with_context(|| format!("opening the bus for {} {}", role.as_str(), args.id))?;
    let span = tracing::info_span!("node", role = role.as_str(), id = args.id, run = %args.run_id);
    let report = run(config, bus, Shutdown::on_signals()).instrument(span).await?;
    tracing::info!(?report, "stopped");
    Ok(report)
}

/// The whole `main` of a role binary: single-threaded numerics, a tokio runtime with two workers
/// (the role's CPU-heavy loop has a thread of its own; the async shell only moves messages), then
/// [`launch`].
pub fn main<C, F, Fut, R>(role: Role, args: &NodeArgs, run: F) -> anyhow::Result<R>
where
    C: RoleConfig,
    F: FnOnce(C, Bus, Shutdown) -> Fut,
    Fut: Future<Output = anyhow::Result<R>>,
    R: Debug,
{
    single_threaded_numerics();
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(launch(role, args, run))
}

/// Makes candle and rayon single-threaded unless `RAYON_NUM_THREADS` says otherwise. Runs first
/// thing in [`main`], before any thread exists (it sets an environment variable).
///
/// Why: the roles' networks are too small to split across threads (two threads were slower in every
/// measurement), and candle asks for its thread count on every matmul; without the variable it
/// re-parses `/proc/cpuinfo` each time, which perf showed as ~17% of an executor's CPU.
fn single_threaded_numerics() {
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        // SAFETY: called at the start of `main`, before any other thread could read the environment.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", "1") };
    }
}
