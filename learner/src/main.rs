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

fn main() -> anyhow::Result<()> {
    node::single_threaded_numerics();
    let args = Args::parse();
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(node::launch(proto::Role::Learner, &args.node, learner::run))?;
    Ok(())
}
