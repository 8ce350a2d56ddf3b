//! `sac-lsp plot`: turns a monitor record (`sac-lsp monitor --out FILE`) into PNG learning curves
//! (`curves` says what is drawn, `chart` draws it with `plotters`).

mod chart;
mod curves;
mod input;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;

/// Canvas width of every chart, pixels.
const WIDTH: u32 = 900;
/// Canvas height, pixels.
const HEIGHT: u32 = 560;

/// `sac-lsp plot` options.
#[derive(Debug, Args)]
#[command(after_help = "Example:\n  sac-lsp plot --input runs/ID/monitor.jsonl")]
pub struct PlotArgs {
    /// The monitor's JSONL record.
    #[arg(long, value_name = "FILE")]
    pub input: PathBuf,
    /// Where to write the PNGs [default: the input's folder].
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
}

/// Writes the charts and prints their paths.
pub fn run(args: &PlotArgs) -> Result<()> {
    let record = input::read(&args.input)?;
    if record.records == 0 {
        bail!("{}: no monitor records (is it a `sac-lsp monitor` JSONL file?)", args.input.display());
    }
    if record.skipped > 0 {
        eprintln!(
            "{}: skipped {} line(s) that are not monitor records",
            args.input.display(),
            record.skipped
        );
    }
    let out_dir = match &args.out_dir {
        Some(dir) => dir.clone(),
        None => args.input.parent().map_or_else(|| PathBuf::from("."), PathBuf::from),
    };
    let out_dir = if out_dir.as_os_str().is_empty() { PathBuf::from(".") } else { out_dir };
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    println!(
        "{}: {} episodes, {} evaluations, {} ticks",
        args.input.display(),
        record.episodes.len(),
        record.evals.len(),
        record.ticks.len()
    );
    for file in curves::charts(&record) {
        let path = out_dir.join(file.file_name);
        node::durable::write(&path, &file.chart.png(WIDTH, HEIGHT)?)?;
        println!("{}", path.display());
    }
    Ok(())
}
