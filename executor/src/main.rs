//! The `executor` binary: `executor::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Executor: steps its own environment with the current policy and publishes transitions.
#[derive(Debug, Parser)]
#[command(
    name = "executor",
    version,
    after_help = "Example (one executor joining a run on another machine):\n  executor --config run.toml --run-id ID --id 3 --connect tcp/10.0.0.1:7447"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Executor, &args.node, executor::run)?;
    Ok(())
}
