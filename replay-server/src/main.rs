//! The `replay-server` binary: `replay_server::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Replay server: owns the prioritized replay buffer and serves it over zenoh.
#[derive(Debug, Parser)]
#[command(
    name = "replay-server",
    version,
    after_help = "Example:\n  replay-server --config deploy/configs/ant-v5.toml --run-id ID --connect tcp/127.0.0.1:7447"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Replay, &args.node, replay_server::run)?;
    Ok(())
}
