//! A 5x7 bitmap font: digits, lowercase letters and the few symbols tick labels, titles and axis
//! names need. Glyphs are spelled as `#`/`.` rows so they can be reviewed by eye.

use super::raster::{Canvas, Pixel, Rgb};

/// Glyph width in font pixels (plus one pixel of spacing when drawn).
pub const GLYPH_WIDTH: i64 = 5;
/// Glyph height in font pixels.
pub const GLYPH_HEIGHT: i64 = 7;

type Glyph = [&'static str; 7];

#[rustfmt::skip]
const GLYPHS: &[(char, Glyph)] = &[
    ('0', [".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."]),
    ('1', ["..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."]),
    ('2', [".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"]),
    ('3', ["#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###."]),
    ('4', ["...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."]),
    ('5', ["#####", "#....", "####.", "....#", "....#", "#...#", ".###."]),
    ('6', ["..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###."]),
    ('7', ["#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#..."]),
    ('8', [".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."]),
    ('9', [".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##.."]),
    ('.', [".....", ".....", ".....", ".....", ".....", ".##..", ".##.."]),
    (',', [".....", ".....", ".....", ".....", ".##..", "..#..", ".#..."]),
    (':', [".....", ".##..", ".##..", ".....", ".##..", ".##..", "....."]),
    ('-', [".....", ".....", ".....", ".####", ".....", ".....", "....."]),
    ('+', [".....", "..#..", "..#..", "#####", "..#..", "..#..", "....."]),
    ('/', [".....", "....#", "...#.", "..#..", ".#...", "#....", "....."]),
    ('(', ["...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#."]),
    (')', [".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#..."]),
    (' ', [".....", ".....", ".....", ".....", ".....", ".....", "....."]),
    ('M', ["#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#"]),
    ('a', [".....", ".....", ".###.", "....#", ".####", "#...#", ".####"]),
    ('b', ["#....", "#....", "#.##.", "##..#", "#...#", "#...#", "####."]),
    ('c', [".....", ".....", ".###.", "#....", "#....", "#...#", ".###."]),
    ('d', ["....#", "....#", ".##.#", "#..##", "#...#", "#...#", ".####"]),
    ('e', [".....", ".....", ".###.", "#...#", "#####", "#....", ".###."]),
    ('f', ["..##.", ".#..#", ".#...", "###..", ".#...", ".#...", ".#..."]),
    ('g', [".....", ".####", "#...#", "#...#", ".####", "....#", ".###."]),
    ('h', ["#....", "#....", "#.##.", "##..#", "#...#", "#...#", "#...#"]),
    ('i', ["..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###."]),
    ('j', ["...#.", ".....", "..##.", "...#.", "...#.", "#..#.", ".##.."]),
    ('k', ["#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#."]),
    ('l', [".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."]),
    ('m', [".....", ".....", "##.#.", "#.#.#", "#.#.#", "#...#", "#...#"]),
    ('n', [".....", ".....", "#.##.", "##..#", "#...#", "#...#", "#...#"]),
    ('o', [".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###."]),
    ('p', [".....", ".....", "####.", "#...#", "####.", "#....", "#...."]),
    ('q', [".....", ".....", ".##.#", "#..##", ".####", "....#", "....#"]),
    ('r', [".....", ".....", "#.##.", "##..#", "#....", "#....", "#...."]),
    ('s', [".....", ".....", ".###.", "#....", ".###.", "....#", "####."]),
    ('t', [".#...", ".#...", "###..", ".#...", ".#...", ".#..#", "..##."]),
    ('u', [".....", ".....", "#...#", "#...#", "#...#", "#..##", ".##.#"]),
    ('v', [".....", ".....", "#...#", "#...#", "#...#", ".#.#.", "..#.."]),
    ('w', [".....", ".....", "#...#", "#...#", "#.#.#", "#.#.#", ".#.#."]),
    ('x', [".....", ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#"]),
    ('y', [".....", ".....", "#...#", "#...#", ".####", "....#", ".###."]),
    ('z', [".....", ".....", "#####", "...#.", "..#..", ".#...", "#####"]),
];

/// Drawn for a character the font lacks, so a gap in the font is visible rather than silent.
const MISSING: Glyph = ["#####", "#...#", "#...#", "#...#", "#...#", "#...#", "#####"];

fn glyph(c: char) -> Option<&'static Glyph> {
    // Upper-case letters other than `M` are drawn lower-case.
    let c = if c == 'M' { c } else { c.to_ascii_lowercase() };
    GLYPHS.iter().find(|(g, _)| *g == c).map(|(_, rows)| rows)
}

/// Whether every character of `text` has a glyph.
#[cfg(test)]
pub fn covers(text: &str) -> bool {
    text.chars().all(|c| glyph(c).is_some())
}

/// Width in canvas pixels of `text` at `scale`.
pub fn text_width(text: &str, scale: i64) -> i64 {
    let n = text.chars().count() as i64;
    if n == 0 { 0 } else { (n * (GLYPH_WIDTH + 1) - 1) * scale }
}

/// Height in canvas pixels of a line of text at `scale`.
pub fn text_height(scale: i64) -> i64 {
    GLYPH_HEIGHT * scale
}

/// Draws `text` with its top-left corner at `at`, each font pixel a `scale` x `scale` square.
pub fn draw(canvas: &mut Canvas, text: &str, at: Pixel, scale: i64, colour: Rgb) {
    let clip = canvas.bounds();
    for (i, c) in text.chars().enumerate() {
        let rows = glyph(c).unwrap_or(&MISSING);
        let left = at.x + i as i64 * (GLYPH_WIDTH + 1) * scale;
        for (row, bits) in rows.iter().enumerate() {
            for (col, bit) in bits.bytes().enumerate() {
                if bit != b'#' {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let p =
                            Pixel { x: left + col as i64 * scale + dx, y: at.y + row as i64 * scale + dy };
                        canvas.set(p, colour, clip);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glyphs_are_well_formed_and_unique() {
        for (i, (c, rows)) in GLYPHS.iter().enumerate() {
            assert!(rows.iter().all(|r| r.len() == 5 && r.bytes().all(|b| b == b'#' || b == b'.')), "{c:?}");
            assert!(GLYPHS[i + 1..].iter().all(|(d, _)| d != c), "{c:?} twice");
            if *c != ' ' {
                assert!(rows.iter().any(|r| r.contains('#')), "{c:?} is blank");
            }
        }
        assert!(covers("0123456789.-e kM return vs env steps (avg 20) updates/s"));
        assert!(!covers("%"));
    }

    #[test]
    fn draws_lit_pixels_where_the_glyph_has_them() {
        let mut c = Canvas::new(40, 20);
        draw(&mut c, "1-", Pixel { x: 2, y: 3 }, 2, Rgb::BLACK);
        // '1' row 0 is "..#..": font column 2 → canvas x 2 + 4 .. 2 + 5, y 3 .. 4.
        assert_eq!(c.get(Pixel { x: 6, y: 3 }), Rgb::BLACK);
        assert_eq!(c.get(Pixel { x: 7, y: 4 }), Rgb::BLACK);
        assert_eq!(c.get(Pixel { x: 2, y: 3 }), Rgb::WHITE);
        // '-' starts 6 font pixels later; its row 3 is ".####".
        assert_eq!(c.get(Pixel { x: 2 + 12 + 2, y: 3 + 6 }), Rgb::BLACK);
        assert_eq!(c.get(Pixel { x: 2 + 12, y: 3 + 6 }), Rgb::WHITE);
        assert_eq!(text_width("1-", 2), 22);
    }
}
