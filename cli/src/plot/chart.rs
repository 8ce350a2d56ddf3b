//! One line chart — title, axes with ticks, grid and labels, a legend, the series as lines (with
//! markers for sparse ones) — drawn with `plotters` and encoded as a compressed PNG.

use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// The font every chart's text is set in: DejaVu Sans, bundled so charts look the same on every
/// machine (its licence is `cli/assets/DejaVuSans-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
/// The family name the charts ask plotters for.
const FAMILY: &str = "sans-serif";

/// An RGB colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rgb {
    /// Red.
    pub r: u8,
    /// Green.
    pub g: u8,
    /// Blue.
    pub b: u8,
}

impl Rgb {
    /// First series (matplotlib's C0).
    pub const BLUE: Rgb = Rgb { r: 31, g: 119, b: 180 };
    /// Second series (matplotlib's C1).
    pub const ORANGE: Rgb = Rgb { r: 255, g: 127, b: 14 };

    fn plotters(self) -> RGBColor {
        RGBColor(self.r, self.g, self.b)
    }
}

/// One data point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Horizontal value.
    pub x: f64,
    /// Vertical value.
    pub y: f64,
}

/// One line of the chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Colour of the line and markers.
    pub colour: Rgb,
    /// The points, joined in order; non-finite ones are left out.
    pub points: Vec<Point>,
    /// Draw a marker at every point (sparse data such as evaluations).
    pub markers: bool,
}

/// A chart to draw.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Above the plot.
    pub title: String,
    /// Under the x axis.
    pub x_label: String,
    /// Beside the y axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

/// The value range one axis shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Low end.
    pub lo: f64,
    /// High end.
    pub hi: f64,
}

impl Range {
    /// `lo..hi` of the values with a margin, never empty (a single value gets ±1, or ±5 %).
    fn covering(values: impl Iterator<Item = f64>, margin: f64) -> Range {
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if lo > hi {
            return Range { lo: 0.0, hi: 1.0 };
        }
        let span = if hi > lo { hi - lo } else { (lo.abs() * 0.1).max(2.0) };
        let pad = if hi > lo { span * margin } else { span / 2.0 };
        Range { lo: lo - pad, hi: hi + pad }
    }
}

impl Chart {
    fn finite(&self) -> impl Iterator<Item = Point> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|p| p.x.is_finite() && p.y.is_finite())
    }

    /// The axes' ranges: the data, with a margin above and below.
    pub fn ranges(&self) -> (Range, Range) {
        (Range::covering(self.finite().map(|p| p.x), 0.0), Range::covering(self.finite().map(|p| p.y), 0.05))
    }

    /// The chart as a `width` x `height` PNG.
    pub fn png(&self, width: u32, height: u32) -> Result<Vec<u8>> {
        crate::picture::png(width, height, &self.draw(width, height)?)
    }

    /// The chart's RGB pixels, row by row from the top.
    pub fn draw(&self, width: u32, height: u32) -> Result<Vec<u8>> {
        static REGISTER: Once = Once::new();
        REGISTER.call_once(|| {
            // The bundled file is a valid font; a failure here would show as missing text.
            let _ = register_font(FAMILY, FontStyle::Normal, FONT);
        });
        let mut rgb = vec![255u8; (width * height * 3) as usize];
        self.draw_on(&mut rgb, width, height).map_err(|e| anyhow!("drawing {:?}: {e}", self.title))?;
        Ok(rgb)
    }

    fn draw_on(&self, rgb: &mut [u8], width: u32, height: u32) -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::with_buffer(rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x, y) = self.ranges();
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, (FAMILY, 22))
            .margin(14)
            .x_label_area_size(52)
            .y_label_area_size(76)
            .build_cartesian_2d(x.lo..x.hi, y.lo..y.hi)?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 16))
            .bold_line_style(RGBColor(225, 225, 225))
            .light_line_style(RGBColor(242, 242, 242))
            .draw()?;
        for series in &self.series {
            let colour = series.colour.plotters();
            let points: Vec<(f64, f64)> = series
                .points
                .iter()
                .filter(|p| p.x.is_finite() && p.y.is_finite())
                .map(|p| (p.x, p.y))
                .collect();
            let markers = series.markers;
            chart
                .draw_series(LineSeries::new(points.iter().copied(), colour.stroke_width(2)))?
                .label(series.name.as_str())
                .legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (20, 0)], colour.stroke_width(2))
                        + Circle::new((10, 0), if markers { 4 } else { 0 }, colour.filled())
                });
            if markers || points.len() == 1 {
                chart.draw_series(points.iter().map(|p| Circle::new(*p, 4, colour.filled())))?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()?;
        if self.finite().next().is_none() {
            let centre = ((width / 2) as i32 - 30, (height / 2) as i32);
            root.draw_text("no data", &(FAMILY, 18).into_text_style(&root), centre)?;
        }
        root.present()?;
        Ok(())
    }
}

/// A tick label: at most three significant decimals, thousands as `k` and millions as `M`.
pub fn tick_label(v: f64) -> String {
    let trim = |s: String| {
        if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
    };
    match v.abs() {
        a if a >= 1e6 => format!("{}M", trim(format!("{:.2}", v / 1e6))),
        a if a >= 1e4 => format!("{}k", trim(format!("{:.1}", v / 1e3))),
        _ => trim(format!("{v:.3}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(points: Vec<Point>) -> Chart {
        Chart {
            title: "return vs env steps".into(),
            x_label: "env steps".into(),
            y_label: "return".into(),
            series: vec![Series { name: "eval".into(), colour: Rgb::ORANGE, points, markers: true }],
        }
    }

    /// Pixels of `colour` in the image's left and right halves.
    fn halves(rgb: &[u8], width: u32, colour: Rgb) -> (usize, usize) {
        let mut counts = (0, 0);
        for (i, p) in rgb.chunks(3).enumerate() {
            if p == [colour.r, colour.g, colour.b] {
                if (i as u32 % width) < width / 2 { counts.0 += 1 } else { counts.1 += 1 }
            }
        }
        counts
    }

    #[test]
    fn a_rising_line_is_drawn_with_its_text_and_decodes() {
        let c = chart(vec![
            Point { x: 0.0, y: 0.0 },
            Point { x: 500_000.0, y: 300.0 },
            Point { x: 1e6, y: 900.0 },
        ]);
        let (width, height) = (480, 320);
        let rgb = c.draw(width, height).unwrap();
        let (left, right) = halves(&rgb, width, Rgb::ORANGE);
        assert!(left > 100 && right > 100, "the line spans the plot: {left} / {right}");
        // Rising: in the right half, the orange pixels sit higher (smaller rows) on average.
        let mean_row = |lo: u32, hi: u32| {
            let rows: Vec<u32> = rgb
                .chunks(3)
                .enumerate()
                .filter(|(i, p)| {
                    let col = *i as u32 % width;
                    (lo..hi).contains(&col) && *p == [255, 127, 14]
                })
                .map(|(i, _)| i as u32 / width)
                .collect();
            rows.iter().sum::<u32>() as f64 / rows.len().max(1) as f64
        };
        assert!(mean_row(width / 2, width) < mean_row(0, width / 2));
        // Text: dark anti-aliased glyph pixels in the title band and under the plot.
        let dark = |rows: std::ops::Range<u32>| {
            rows.flat_map(|r| (0..width).map(move |c| (r * width + c) as usize * 3))
                .filter(|i| rgb[*i] < 100 && rgb[i + 1] < 100 && rgb[i + 2] < 100)
                .count()
        };
        assert!(dark(0..36) > 50, "the title");
        assert!(dark(height - 52..height) > 50, "tick labels and the axis name");
        assert_eq!(&rgb[..3], &[255, 255, 255], "white corner");
        let png = c.png(width, height).unwrap();
        let info = png::Decoder::new(std::io::Cursor::new(&png)).read_info().unwrap().info().clone();
        assert_eq!((info.width, info.height), (width, height));
        assert!(png.len() < rgb.len() / 4, "compressed: {} bytes", png.len());
    }

    #[test]
    fn non_finite_points_are_skipped_and_no_data_still_draws() {
        let c = chart(vec![Point { x: f64::NAN, y: 1.0 }, Point { x: 1.0, y: 2.0 }]);
        let (x, y) = c.ranges();
        assert!(x.lo < 1.0 && 1.0 < x.hi && y.lo < 2.0 && 2.0 < y.hi, "{x:?} {y:?}");
        assert_eq!(chart(Vec::new()).draw(300, 200).unwrap().len(), 300 * 200 * 3);
    }

    #[test]
    fn tick_labels_stay_short() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(0.125), "0.125");
        assert_eq!(tick_label(2500.0), "2500");
        assert_eq!(tick_label(250_000.0), "250k");
        assert_eq!(tick_label(1_500_000.0), "1.5M");
        assert_eq!(tick_label(-40_000.0), "-40k");
    }
}
