//! Pictures to files: PNG encoding of RGB pictures (charts, rendered frames), through the `png` crate.

use anyhow::Result;

/// `rgb` (`width · height · 3` bytes, rows from the top) as a PNG, compressed as well as the
/// encoder can: these files are committed and shown in READMEs.
pub fn png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Best);
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    encoder.write_header()?.write_image_data(rgb)?;
    Ok(out)
}
