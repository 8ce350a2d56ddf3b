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

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    node::launch(proto::Role::Param, &args.node, param_server::run).await?;
    Ok(())
}
