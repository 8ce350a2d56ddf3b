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
    let args = Args::parse();
    let n = &args.node;
    match args.role {
        Which::Replay => node::main(Role::Replay, n, replay_server::run).map(drop),
        Which::Param => node::main(Role::Param, n, param_server::run).map(drop),
        Which::Learner => node::main(Role::Learner, n, learner::run).map(drop),
        Which::Executor => node::main(Role::Executor, n, executor::run).map(drop),
    }
}
