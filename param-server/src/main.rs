//! The `param-server` binary: `param_server::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Parameter server: the latest weights keyed by the global step, and the executors' barrier.
#[derive(Debug, Parser)]
#[command(name = "param-server", version)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Param, &args.node, param_server::run)?;
    Ok(())
}
