//! `cluster-node <role> [bus options]`: any role behind the shared node launcher, in one binary, so
//! the cluster's own integration tests can start real processes (`CARGO_BIN_EXE_cluster-node`)
//! across network namespaces. Users run the per-role binaries; this is the same code.

use clap::{Parser, ValueEnum};
use node::NodeArgs;
use proto::Role;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Which {
    Replay,
    Param,
    Learner,
    Executor,
}

/// One role of a distributed SAC-LSP run.
#[derive(Debug, Parser)]
#[command(name = "cluster-node")]
struct Args {
    /// The role to run.
    #[arg(value_enum)]
    role: Which,
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    node::single_threaded_numerics();
    let args = Args::parse();
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(run(args))
}

async fn run(args: Args) -> anyhow::Result<()> {
    let n = &args.node;
    match args.role {
        Which::Replay => node::launch(Role::Replay, n, replay_server::run).await.map(drop),
        Which::Param => node::launch(Role::Param, n, param_server::run).await.map(drop),
        Which::Learner => node::launch(Role::Learner, n, learner::run).await.map(drop),
        Which::Executor => node::launch(Role::Executor, n, executor::run).await.map(drop),
    }
}
