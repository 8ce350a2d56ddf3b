//! A tiny RGB rasterizer: filled rectangles, thick Bresenham lines and square markers, clipped to
//! the canvas (and, for data, to a clip rectangle, so outliers cannot draw over the axes).

use super::png::RgbImage;

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
    /// The background.
    pub const WHITE: Rgb = Rgb { r: 255, g: 255, b: 255 };
    /// Axes and text.
    pub const BLACK: Rgb = Rgb { r: 0, g: 0, b: 0 };
    /// Grid lines.
    pub const LIGHT_GREY: Rgb = Rgb { r: 225, g: 225, b: 225 };
    /// First series (matplotlib's C0).
    pub const BLUE: Rgb = Rgb { r: 31, g: 119, b: 180 };
    /// Second series (matplotlib's C1).
    pub const ORANGE: Rgb = Rgb { r: 255, g: 127, b: 14 };
}

/// A pixel position; may lie outside the canvas (drawing clips).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pixel {
    /// Column, from the left.
    pub x: i64,
    /// Row, from the top.
    pub y: i64,
}

/// A rectangle of pixels, `left..=right` by `top..=bottom`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Leftmost column.
    pub left: i64,
    /// Topmost row.
    pub top: i64,
    /// Rightmost column.
    pub right: i64,
    /// Bottom row.
    pub bottom: i64,
}

impl Rect {
    fn contains(&self, p: Pixel) -> bool {
        (self.left..=self.right).contains(&p.x) && (self.top..=self.bottom).contains(&p.y)
    }
}

/// An image being drawn, white to start with.
#[derive(Debug, Clone)]
pub struct Canvas {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
}

impl Canvas {
    /// A white `width` x `height` canvas.
    pub fn new(width: u32, height: u32) -> Canvas {
        let white = [Rgb::WHITE.r, Rgb::WHITE.g, Rgb::WHITE.b];
        Canvas { width, height, pixels: white.repeat(width as usize * height as usize) }
    }

    /// The whole canvas as a rectangle.
    pub fn bounds(&self) -> Rect {
        Rect { left: 0, top: 0, right: i64::from(self.width) - 1, bottom: i64::from(self.height) - 1 }
    }

    /// Sets one pixel if it lies within `clip` and the canvas.
    pub fn set(&mut self, p: Pixel, colour: Rgb, clip: Rect) {
        if !clip.contains(p) || !self.bounds().contains(p) {
            return;
        }
        let at = (p.y as usize * self.width as usize + p.x as usize) * 3;
        self.pixels[at..at + 3].copy_from_slice(&[colour.r, colour.g, colour.b]);
    }

    /// The colour of pixel `p` (white outside the canvas).
    #[cfg(test)]
    pub fn get(&self, p: Pixel) -> Rgb {
        if !self.bounds().contains(p) {
            return Rgb::WHITE;
        }
        let at = (p.y as usize * self.width as usize + p.x as usize) * 3;
        Rgb { r: self.pixels[at], g: self.pixels[at + 1], b: self.pixels[at + 2] }
    }

    /// Fills `rect`.
    pub fn fill(&mut self, rect: Rect, colour: Rgb) {
        let clip = self.bounds();
        for y in rect.top..=rect.bottom {
            for x in rect.left..=rect.right {
                self.set(Pixel { x, y }, colour, clip);
            }
        }
    }

    /// The outline of `rect`, one pixel wide.
    pub fn outline(&mut self, rect: Rect, colour: Rgb) {
        let Rect { left, top, right, bottom } = rect;
        self.fill(Rect { left, top, right, bottom: top }, colour);
        self.fill(Rect { left, top: bottom, right, bottom }, colour);
        self.fill(Rect { left, top, right: left, bottom }, colour);
        self.fill(Rect { left: right, top, right, bottom }, colour);
    }

    /// A line from `a` to `b`, `width` pixels thick (a square brush), clipped to `clip`.
    pub fn line(&mut self, a: Pixel, b: Pixel, colour: Rgb, width: i64, clip: Rect) {
        // Bresenham over every octant; far-off endpoints (clipped outliers) would make the walk long,
        // so they are first pulled in along the line to a box around the clip rectangle.
        let (Some(a), Some(b)) = (pull_in(a, b, clip), pull_in(b, a, clip)) else { return };
        let (dx, dy) = ((b.x - a.x).abs(), -(b.y - a.y).abs());
        let (sx, sy) = ((b.x - a.x).signum(), (b.y - a.y).signum());
        let (mut x, mut y, mut err) = (a.x, a.y, dx + dy);
        loop {
            self.brush(Pixel { x, y }, colour, width, clip);
            if x == b.x && y == b.y {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// A filled square marker of side `size` centred on `p`.
    pub fn marker(&mut self, p: Pixel, colour: Rgb, size: i64, clip: Rect) {
        self.brush(p, colour, size, clip);
    }

    fn brush(&mut self, p: Pixel, colour: Rgb, size: i64, clip: Rect) {
        let lo = -(size - 1) / 2;
        for dy in lo..lo + size.max(1) {
            for dx in lo..lo + size.max(1) {
                self.set(Pixel { x: p.x + dx, y: p.y + dy }, colour, clip);
            }
        }
    }

    /// The finished image.
    pub fn into_image(self) -> RgbImage {
        RgbImage { width: self.width, height: self.height, pixels: self.pixels }
    }
}

/// Moves `from` toward `to` until it lies within a margin of `clip` (the part of the segment outside
/// draws nothing anyway). `None` if the whole segment misses that box.
fn pull_in(from: Pixel, to: Pixel, clip: Rect) -> Option<Pixel> {
    const MARGIN: i64 = 16;
    let boxed = Rect {
        left: clip.left - MARGIN,
        top: clip.top - MARGIN,
        right: clip.right + MARGIN,
        bottom: clip.bottom + MARGIN,
    };
    if boxed.contains(from) {
        return Some(from);
    }
    // Liang-Barsky on the parameter t in [0, 1] of from + t (to - from).
    let (dx, dy) = ((to.x - from.x) as f64, (to.y - from.y) as f64);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let edges = [
        (-dx, (from.x - boxed.left) as f64),
        (dx, (boxed.right - from.x) as f64),
        (-dy, (from.y - boxed.top) as f64),
        (dy, (boxed.bottom - from.y) as f64),
    ];
    for (p, q) in edges {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then(|| Pixel { x: from.x + (t0 * dx).round() as i64, y: from.y + (t0 * dy).round() as i64 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_cover_their_endpoints_and_stay_in_the_clip() {
        let mut c = Canvas::new(50, 40);
        let clip = Rect { left: 5, top: 5, right: 44, bottom: 34 };
        c.line(Pixel { x: 10, y: 10 }, Pixel { x: 40, y: 30 }, Rgb::BLUE, 1, clip);
        assert_eq!(c.get(Pixel { x: 10, y: 10 }), Rgb::BLUE);
        assert_eq!(c.get(Pixel { x: 40, y: 30 }), Rgb::BLUE);
        assert_eq!(c.get(Pixel { x: 25, y: 20 }), Rgb::BLUE, "midpoint");
        assert_eq!(c.get(Pixel { x: 10, y: 30 }), Rgb::WHITE);
        // An outlier far outside: drawn up to the clip edge only, and quickly.
        c.line(Pixel { x: 20, y: 20 }, Pixel { x: 20, y: -1_000_000_000 }, Rgb::ORANGE, 1, clip);
        assert_eq!(c.get(Pixel { x: 20, y: 5 }), Rgb::ORANGE);
        assert_eq!(c.get(Pixel { x: 20, y: 4 }), Rgb::WHITE);
        // Entirely outside: nothing.
        let before = c.clone().into_image();
        c.line(Pixel { x: -100, y: -100 }, Pixel { x: -50, y: -300 }, Rgb::BLACK, 3, clip);
        assert_eq!(c.into_image(), before);
    }

    #[test]
    fn thick_lines_and_markers_are_wider() {
        let mut c = Canvas::new(20, 20);
        let clip = c.bounds();
        c.line(Pixel { x: 2, y: 10 }, Pixel { x: 17, y: 10 }, Rgb::BLACK, 3, clip);
        assert_eq!(c.get(Pixel { x: 9, y: 9 }), Rgb::BLACK);
        assert_eq!(c.get(Pixel { x: 9, y: 11 }), Rgb::BLACK);
        assert_eq!(c.get(Pixel { x: 9, y: 12 }), Rgb::WHITE);
        c.marker(Pixel { x: 5, y: 3 }, Rgb::ORANGE, 5, clip);
        assert_eq!(c.get(Pixel { x: 3, y: 1 }), Rgb::ORANGE);
        assert_eq!(c.get(Pixel { x: 7, y: 5 }), Rgb::ORANGE);
        assert_eq!(c.get(Pixel { x: 8, y: 5 }), Rgb::WHITE);
    }
}
