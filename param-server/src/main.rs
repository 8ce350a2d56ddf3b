//! The `param-server` binary: `param_server::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Parameter server: the latest weights keyed by the global step, and the executors' barrier.
#[derive(Debug, Parser)]
#[command(
    name = "param-server",
    version,
    after_help = "Example:\n  param-server --config deploy/configs/ant-v5.toml --run-id ID --listen tcp/0.0.0.0:7447"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Param, &args.node, param_server::run)?;
    Ok(())
}
