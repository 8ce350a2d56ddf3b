//! The `learner` binary: `learner::run` behind the shared node launcher.

use clap::Parser;
use node::NodeArgs;

/// Learner: trains SAC-LSP on batches from the replay server and publishes weights.
#[derive(Debug, Parser)]
#[command(name = "learner", version)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::launch(proto::Role::Learner, &args.node, learner::run).await?;
    Ok(())
}
