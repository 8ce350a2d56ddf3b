//! One line chart: title, axes box with ticks, grid and numeric labels, a legend, and the series as
//! lines (optionally with markers), drawn onto a [`Canvas`].

use super::axis::Axis;
use super::font::{self, text_height, text_width};
use super::raster::{Canvas, Pixel, Rect, Rgb};

/// Text scale: each font pixel is this many canvas pixels.
const TEXT_SCALE: i64 = 2;
/// Tick mark length in pixels.
const TICK_LEN: i64 = 6;
/// Gap between things, in pixels.
const GAP: i64 = 8;
/// Line width of the series.
const LINE_WIDTH: i64 = 2;
/// Side of a marker square.
const MARKER_SIZE: i64 = 7;

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
    /// Above the y axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

/// Where the data goes on the canvas, and how values map to pixels.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The plot area (inside the axes box).
    pub area: Rect,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
}

impl Frame {
    /// The pixel of a data point.
    pub fn pixel(&self, p: Point) -> Pixel {
        let a = self.area;
        let x = a.left as f64 + self.x.fraction(p.x) * (a.right - a.left) as f64;
        let y = a.bottom as f64 - self.y.fraction(p.y) * (a.bottom - a.top) as f64;
        // Saturating casts: far outliers land far outside and are clipped.
        Pixel { x: x.round() as i64, y: y.round() as i64 }
    }
}

impl Chart {
    fn points(&self) -> impl Iterator<Item = Point> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|p| p.x.is_finite() && p.y.is_finite())
    }

    /// The axes for the data and the plot area for a `width` x `height` canvas.
    pub fn frame(&self, width: u32, height: u32) -> Frame {
        let range = |value: fn(&Point) -> f64| {
            self.points()
                .map(|p| value(&p))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)))
        };
        let (x_min, x_max) = range(|p| p.x);
        let (y_min, y_max) = range(|p| p.y);
        let x = Axis::covering(x_min, x_max);
        let y = Axis::covering(y_min, y_max);
        let widest_y_label =
            y.ticks().iter().map(|t| text_width(&y.label(*t), TEXT_SCALE)).max().unwrap_or(0);
        let line = text_height(TEXT_SCALE);
        let area = Rect {
            left: GAP * 2 + widest_y_label + TICK_LEN,
            top: GAP * 4 + line * 2,
            right: i64::from(width) - GAP * 3,
            bottom: i64::from(height) - GAP * 4 - line * 2,
        };
        Frame { area, x, y }
    }

    /// Draws the chart on a white `width` x `height` canvas.
    pub fn render(&self, width: u32, height: u32) -> Canvas {
        let mut canvas = Canvas::new(width, height);
        let frame = self.frame(width, height);
        let area = frame.area;
        let line = text_height(TEXT_SCALE);
        let centred = |text: &str, x: i64| x - text_width(text, TEXT_SCALE) / 2;

        font::draw(
            &mut canvas,
            &self.title,
            Pixel { x: centred(&self.title, i64::from(width) / 2), y: GAP },
            TEXT_SCALE,
            Rgb::BLACK,
        );
        font::draw(
            &mut canvas,
            &self.y_label,
            Pixel { x: area.left, y: GAP * 2 + line },
            TEXT_SCALE,
            Rgb::BLACK,
        );
        let x_label_at = Pixel {
            x: centred(&self.x_label, (area.left + area.right) / 2),
            y: area.bottom + GAP * 3 + line,
        };
        font::draw(&mut canvas, &self.x_label, x_label_at, TEXT_SCALE, Rgb::BLACK);

        for tick in frame.x.ticks() {
            let px = frame.pixel(Point { x: tick, y: frame.y.lo }).x;
            canvas.fill(
                Rect { left: px, top: area.top + 1, right: px, bottom: area.bottom - 1 },
                Rgb::LIGHT_GREY,
            );
            canvas.fill(
                Rect { left: px, top: area.bottom, right: px, bottom: area.bottom + TICK_LEN },
                Rgb::BLACK,
            );
            let label = frame.x.label(tick);
            let at = Pixel { x: centred(&label, px), y: area.bottom + TICK_LEN + GAP / 2 };
            font::draw(&mut canvas, &label, at, TEXT_SCALE, Rgb::BLACK);
        }
        for tick in frame.y.ticks() {
            let py = frame.pixel(Point { x: frame.x.lo, y: tick }).y;
            canvas.fill(
                Rect { left: area.left + 1, top: py, right: area.right - 1, bottom: py },
                Rgb::LIGHT_GREY,
            );
            canvas
                .fill(Rect { left: area.left - TICK_LEN, top: py, right: area.left, bottom: py }, Rgb::BLACK);
            let label = frame.y.label(tick);
            let at = Pixel {
                x: area.left - TICK_LEN - GAP / 2 - text_width(&label, TEXT_SCALE),
                y: py - line / 2,
            };
            font::draw(&mut canvas, &label, at, TEXT_SCALE, Rgb::BLACK);
        }
        canvas.outline(area, Rgb::BLACK);

        let inside =
            Rect { left: area.left + 1, top: area.top + 1, right: area.right - 1, bottom: area.bottom - 1 };
        for series in &self.series {
            let pixels: Vec<Pixel> = series
                .points
                .iter()
                .filter(|p| p.x.is_finite() && p.y.is_finite())
                .map(|p| frame.pixel(*p))
                .collect();
            for pair in pixels.windows(2) {
                canvas.line(pair[0], pair[1], series.colour, LINE_WIDTH, inside);
            }
            if series.markers || pixels.len() == 1 {
                for p in &pixels {
                    canvas.marker(*p, series.colour, MARKER_SIZE, inside);
                }
            }
        }
        self.legend(&mut canvas, area);
        if self.points().next().is_none() {
            let text = "no data";
            let at =
                Pixel { x: centred(text, (area.left + area.right) / 2), y: (area.top + area.bottom) / 2 };
            font::draw(&mut canvas, text, at, TEXT_SCALE, Rgb::BLACK);
        }
        canvas
    }

    /// A sample line and the name of each series, top left inside the plot (learning curves start
    /// low, so that corner is usually empty).
    fn legend(&self, canvas: &mut Canvas, area: Rect) {
        let line = text_height(TEXT_SCALE);
        let clip = canvas.bounds();
        for (i, series) in self.series.iter().enumerate() {
            let top = area.top + GAP + i as i64 * (line + GAP);
            let mid = top + line / 2;
            let start = Pixel { x: area.left + GAP, y: mid };
            let end = Pixel { x: area.left + GAP + 24, y: mid };
            canvas.line(start, end, series.colour, LINE_WIDTH, clip);
            if series.markers {
                canvas.marker(Pixel { x: area.left + GAP + 12, y: mid }, series.colour, MARKER_SIZE, clip);
            }
            font::draw(canvas, &series.name, Pixel { x: end.x + GAP, y: top }, TEXT_SCALE, Rgb::BLACK);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(points: Vec<Point>) -> Chart {
        Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series { name: "s".into(), colour: Rgb::BLUE, points, markers: true }],
        }
    }

    #[test]
    fn the_series_is_drawn_where_the_frame_maps_it() {
        // Interior points (a data maximum on a whole step would sit on the axes box).
        let c =
            chart(vec![Point { x: 10.0, y: 5.0 }, Point { x: 100.0, y: 37.0 }, Point { x: 190.0, y: 20.0 }]);
        let frame = c.frame(640, 400);
        assert_eq!((frame.x.lo, frame.x.hi, frame.y.lo, frame.y.hi), (0.0, 200.0, 0.0, 40.0));
        let canvas = c.render(640, 400);
        // Rounding may put the line one pixel off the ideal one.
        let near = |p: Point| {
            let at = frame.pixel(p);
            (-1..=1)
                .any(|dy| (-1..=1).any(|dx| canvas.get(Pixel { x: at.x + dx, y: at.y + dy }) == Rgb::BLUE))
        };
        for p in [Point { x: 55.0, y: 21.0 }, Point { x: 145.0, y: 28.5 }] {
            assert!(near(p), "{p:?}");
        }
        // Markers sit exactly on the points.
        for p in &c.series[0].points {
            assert_eq!(canvas.get(frame.pixel(*p)), Rgb::BLUE, "{p:?}");
        }
        // Off the line: background or grid, not the series.
        let off = canvas.get(frame.pixel(Point { x: 50.0, y: 35.0 }));
        assert!(off == Rgb::WHITE || off == Rgb::LIGHT_GREY, "{off:?}");
        // The axes box.
        assert_eq!(canvas.get(Pixel { x: frame.area.left, y: frame.area.bottom }), Rgb::BLACK);
        assert_eq!(canvas.get(Pixel { x: frame.area.right, y: frame.area.top }), Rgb::BLACK);
    }

    #[test]
    fn non_finite_points_are_skipped_and_no_data_still_renders() {
        let c = chart(vec![Point { x: f64::NAN, y: 1.0 }, Point { x: 1.0, y: 2.0 }]);
        assert_eq!(c.frame(300, 200).x, Axis::covering(1.0, 1.0));
        let empty = chart(Vec::new()).render(300, 200);
        assert_eq!(empty.into_image().pixels.len(), 300 * 200 * 3);
    }
}
