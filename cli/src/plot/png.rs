//! A minimal PNG encoder: 8-bit RGB, no filtering, and zlib "stored" (uncompressed) deflate blocks.
//! Plots are small and written rarely, so size does not matter; writing the format by hand keeps the
//! workspace free of an image crate.

/// The 8 bytes every PNG starts with.
pub const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];

/// The most a stored deflate block can hold.
const MAX_STORED_BLOCK: usize = 65_535;

/// An RGB image, row-major, 3 bytes per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 3` bytes.
    pub pixels: Vec<u8>,
}

/// Why an image cannot be encoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SizeMismatch {
    /// Bytes `width * height * 3` needs.
    pub expected: usize,
    /// Bytes given.
    pub found: usize,
}

impl std::fmt::Display for SizeMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RGB image needs {} bytes, has {}", self.expected, self.found)
    }
}

impl std::error::Error for SizeMismatch {}

/// The PNG file for `image`.
pub fn encode(image: &RgbImage) -> Result<Vec<u8>, SizeMismatch> {
    let row = image.width as usize * 3;
    let expected = row * image.height as usize;
    if image.pixels.len() != expected || image.width == 0 || image.height == 0 {
        return Err(SizeMismatch { expected, found: image.pixels.len() });
    }
    // Each scanline is preceded by its filter type; 0 = none.
    let mut raw = Vec::with_capacity(expected + image.height as usize);
    for line in image.pixels.chunks_exact(row) {
        raw.push(0);
        raw.extend_from_slice(line);
    }
    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&image.width.to_be_bytes());
    ihdr.extend_from_slice(&image.height.to_be_bytes());
    // Bit depth 8, colour type 2 (RGB), deflate, adaptive filtering, no interlace.
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);

    let mut png = SIGNATURE.to_vec();
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &zlib_stored(&raw));
    chunk(&mut png, b"IEND", &[]);
    Ok(png)
}

/// One chunk: length, type, data, CRC-32 of type and data.
fn chunk(png: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    // PNG caps chunk lengths at 2^31 - 1; a 1000x1000 plot is 3 MB.
    png.extend_from_slice(&(data.len() as u32).to_be_bytes());
    png.extend_from_slice(kind);
    png.extend_from_slice(data);
    let mut crc = crc32fast::Hasher::new();
    crc.update(kind);
    crc.update(data);
    png.extend_from_slice(&crc.finalize().to_be_bytes());
}

/// A zlib stream (RFC 1950) of stored deflate blocks (RFC 1951 §3.2.4).
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let blocks = data.len().div_ceil(MAX_STORED_BLOCK).max(1);
    let mut out = Vec::with_capacity(data.len() + 5 * blocks + 6);
    // CMF 0x78: deflate, 32K window; FLG 0x01 makes CMF*256+FLG a multiple of 31 (no dictionary).
    out.extend_from_slice(&[0x78, 0x01]);
    let mut chunks = data.chunks(MAX_STORED_BLOCK).peekable();
    if chunks.peek().is_none() {
        out.extend_from_slice(&[1, 0, 0, 0xff, 0xff]);
    }
    while let Some(block) = chunks.next() {
        let last = chunks.peek().is_none();
        // BFINAL in bit 0, BTYPE 00 (stored); the rest of the byte pads to the boundary.
        out.push(u8::from(last));
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

/// Adler-32 (RFC 1950 §8), zlib's checksum of the uncompressed data.
fn adler32(data: &[u8]) -> u32 {
    const MOD: u32 = 65_521;
    let (mut a, mut b) = (1u32, 0u32);
    // 5552 bytes is the most that can be summed before b overflows u32.
    for block in data.chunks(5552) {
        for &byte in block {
            a += u32::from(byte);
            b += a;
        }
        a %= MOD;
        b %= MOD;
    }
    (b << 16) | a
}

#[cfg(test)]
pub mod decode {
    //! Reads back exactly what [`super::encode`] writes, to test it.

    /// The parts of a PNG the tests look at.
    #[derive(Debug)]
    pub struct Decoded {
        pub width: u32,
        pub height: u32,
        pub chunk_types: Vec<String>,
        /// The inflated IDAT: filter byte plus RGB per row.
        pub raw: Vec<u8>,
    }

    impl Decoded {
        /// The RGB of pixel (x, y).
        pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
            let row = 1 + 3 * self.width as usize;
            let at = y as usize * row + 1 + 3 * x as usize;
            [self.raw[at], self.raw[at + 1], self.raw[at + 2]]
        }
    }

    fn be32(b: &[u8]) -> u32 {
        u32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }

    pub fn decode(png: &[u8]) -> Decoded {
        assert_eq!(&png[..8], &super::SIGNATURE);
        let mut at = 8;
        let (mut width, mut height, mut idat, mut chunk_types) = (0, 0, Vec::new(), Vec::new());
        while at < png.len() {
            let len = be32(&png[at..]) as usize;
            let kind = &png[at + 4..at + 8];
            let data = &png[at + 8..at + 8 + len];
            let crc = be32(&png[at + 8 + len..]);
            let mut hasher = crc32fast::Hasher::new();
            hasher.update(kind);
            hasher.update(data);
            assert_eq!(hasher.finalize(), crc, "chunk CRC");
            match kind {
                b"IHDR" => {
                    width = be32(data);
                    height = be32(&data[4..]);
                    assert_eq!(&data[8..], &[8, 2, 0, 0, 0]);
                }
                b"IDAT" => idat.extend_from_slice(data),
                _ => {}
            }
            chunk_types.push(String::from_utf8(kind.to_vec()).unwrap());
            at += 12 + len;
        }
        Decoded { width, height, chunk_types, raw: inflate_stored(&idat) }
    }

    fn inflate_stored(z: &[u8]) -> Vec<u8> {
        assert_eq!((u16::from(z[0]) << 8 | u16::from(z[1])) % 31, 0, "zlib header check");
        assert_eq!(z[0] & 0x0f, 8, "deflate");
        let mut at = 2;
        let mut out = Vec::new();
        loop {
            let header = z[at];
            assert_eq!(header >> 1, 0, "stored block");
            let len = u16::from_le_bytes([z[at + 1], z[at + 2]]);
            let nlen = u16::from_le_bytes([z[at + 3], z[at + 4]]);
            assert_eq!(len, !nlen);
            out.extend_from_slice(&z[at + 5..at + 5 + len as usize]);
            at += 5 + len as usize;
            if header & 1 == 1 {
                break;
            }
        }
        assert_eq!(be32(&z[at..]), super::adler32(&out), "adler32");
        assert_eq!(at + 4, z.len(), "trailing bytes");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adler32_matches_known_values() {
        assert_eq!(adler32(b""), 1);
        assert_eq!(adler32(b"Wikipedia"), 0x11e6_0398);
        // Long input: exercises the modulo between blocks.
        let long = vec![0xffu8; 100_000];
        let (mut a, mut b) = (1u64, 0u64);
        for &x in &long {
            a = (a + u64::from(x)) % 65_521;
            b = (b + a) % 65_521;
        }
        assert_eq!(adler32(&long), ((b << 16) | a) as u32);
    }

    #[test]
    fn encodes_signature_header_and_pixels() {
        // Large enough for several stored blocks.
        let (width, height) = (300u32, 200u32);
        let mut pixels = vec![255u8; (width * height * 3) as usize];
        let red = |x: u32, y: u32| ((y * width + x) * 3) as usize;
        pixels[red(7, 11)] = 200;
        pixels[red(7, 11) + 1] = 0;
        let png = encode(&RgbImage { width, height, pixels }).unwrap();
        assert_eq!(&png[..8], &SIGNATURE);
        assert_eq!(&png[12..16], b"IHDR");
        assert_eq!(u32::from_be_bytes([png[16], png[17], png[18], png[19]]), width);
        assert_eq!(u32::from_be_bytes([png[20], png[21], png[22], png[23]]), height);
        let d = decode::decode(&png);
        assert_eq!(d.chunk_types, ["IHDR", "IDAT", "IEND"]);
        assert_eq!(d.raw.len(), (height * (1 + 3 * width)) as usize);
        assert!(d.raw.len() > 2 * MAX_STORED_BLOCK, "three stored blocks");
        assert!((0..height).all(|y| d.raw[(y * (1 + 3 * width)) as usize] == 0), "filter bytes");
        assert_eq!(d.pixel(7, 11), [200, 0, 255]);
        assert_eq!(d.pixel(8, 11), [255, 255, 255]);
    }

    #[test]
    fn rejects_a_wrong_buffer_size() {
        let bad = RgbImage { width: 2, height: 2, pixels: vec![0; 11] };
        assert_eq!(encode(&bad), Err(SizeMismatch { expected: 12, found: 11 }));
    }
}
