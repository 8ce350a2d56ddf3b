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
    node::single_threaded_numerics();
    let args = Args::parse();
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(node::launch(proto::Role::Executor, &args.node, executor::run))?;
    Ok(())
}
