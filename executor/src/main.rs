//! The `executor` binary: `executor::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Executor: steps its own environment with the current policy and publishes transitions.
#[derive(Debug, Parser)]
#[command(name = "executor", version)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Executor, &args.node, executor::run)?;
    Ok(())
}
