//! `sac-lsp plot`: turns a monitor record (`sac-lsp monitor --out FILE`) into PNG learning curves.
//! Everything, down to the PNG encoder and the font, is written here, because no plotting or image
//! crate is a dependency of the workspace.

mod axis;
mod chart;
mod curves;
mod font;
mod input;
pub mod png;
mod raster;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;

/// Canvas width of every chart, pixels.
const WIDTH: u32 = 900;
/// Canvas height, pixels.
const HEIGHT: u32 = 560;

/// `sac-lsp plot` options.
#[derive(Debug, Args)]
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
        let image = file.chart.render(WIDTH, HEIGHT).into_image();
        let bytes = png::encode(&image)?;
        let path = out_dir.join(file.file_name);
        std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
        println!("{}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::chart::{Chart, Point, Series};
    use super::png::decode;
    use super::raster::Rgb;

    /// The whole pipeline, chart to PNG bytes and back: the line's pixels are coloured where the
    /// frame puts them, and the corners stay white.
    #[test]
    fn a_rendered_chart_decodes_with_its_line_in_place() {
        let chart = Chart {
            title: "return vs env steps".into(),
            x_label: "env steps".into(),
            y_label: "return".into(),
            series: vec![Series {
                name: "eval".into(),
                colour: Rgb::ORANGE,
                points: vec![Point { x: 100.0, y: 50.0 }, Point { x: 900.0, y: 450.0 }],
                markers: true,
            }],
        };
        let (width, height) = (400, 300);
        let frame = chart.frame(width, height);
        let png = super::png::encode(&chart.render(width, height).into_image()).unwrap();
        let d = decode::decode(&png);
        assert_eq!((d.width, d.height), (width, height));
        assert_eq!(d.raw.len(), (height * (1 + 3 * width)) as usize);
        let orange = [Rgb::ORANGE.r, Rgb::ORANGE.g, Rgb::ORANGE.b];
        for p in [Point { x: 100.0, y: 50.0 }, Point { x: 900.0, y: 450.0 }] {
            let at = frame.pixel(p);
            assert_eq!(d.pixel(at.x as u32, at.y as u32), orange, "{p:?}");
        }
        // Somewhere along the diagonal, within a pixel of the ideal line.
        let mid = frame.pixel(Point { x: 500.0, y: 250.0 });
        let on_line = (-1..=1i64)
            .any(|dy| (-1..=1i64).any(|dx| d.pixel((mid.x + dx) as u32, (mid.y + dy) as u32) == orange));
        assert!(on_line);
        assert_eq!(d.pixel(0, 0), [255, 255, 255]);
        assert_eq!(d.pixel(width - 1, height - 1), [255, 255, 255]);
    }
}
