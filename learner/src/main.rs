//! The `learner` binary: `learner::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Learner: trains SAC-LSP on batches from the replay server and publishes weights.
#[derive(Debug, Parser)]
#[command(
    name = "learner",
    version,
    after_help = "Example:\n  learner --config deploy/configs/ant-v5.toml --run-id ID --connect tcp/127.0.0.1:7447"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::main(proto::Role::Learner, &args.node, learner::run)?;
    Ok(())
}
