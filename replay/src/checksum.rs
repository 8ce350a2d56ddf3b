//! A streaming 64-bit checksum for snapshots.
//!
//! Hand-rolled to keep the crate's dependencies at serde/thiserror/rand: snapshots are hundreds of
//! megabytes, so it consumes 8-byte words (a byte-wise FNV would cost several cycles per byte).
//! Each step `state = rotl((state ^ word) · K, 31)` is a bijection of the state, so any change
//! confined to one word always changes the result; it guards against truncation, torn writes and
//! bit rot, not against deliberate tampering.

const K: u64 = 0x9e37_79b9_7f4a_7c15;

/// Checksum state; feed bytes in any split, the result depends only on the concatenation.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Checksum {
    state: u64,
    pending: [u8; 8],
    pending_len: usize,
    length: u64,
}

impl Checksum {
    pub fn new() -> Self {
        Self { state: 0xcbf2_9ce4_8422_2325, pending: [0; 8], pending_len: 0, length: 0 }
    }

    pub fn update(&mut self, mut bytes: &[u8]) {
        self.length += bytes.len() as u64;
        if self.pending_len > 0 {
            let take = (8 - self.pending_len).min(bytes.len());
            self.pending[self.pending_len..self.pending_len + take].copy_from_slice(&bytes[..take]);
            self.pending_len += take;
            bytes = &bytes[take..];
            if self.pending_len < 8 {
                return;
            }
            self.mix(u64::from_le_bytes(self.pending));
            self.pending_len = 0;
        }
        let mut words = bytes.chunks_exact(8);
        for word in &mut words {
            let mut w = [0; 8];
            w.copy_from_slice(word);
            self.mix(u64::from_le_bytes(w));
        }
        let rest = words.remainder();
        self.pending[..rest.len()].copy_from_slice(rest);
        self.pending_len = rest.len();
    }

    pub fn finish(&self) -> u64 {
        let mut last = *self;
        let mut tail = [0; 8];
        tail[..self.pending_len].copy_from_slice(&self.pending[..self.pending_len]);
        last.mix(u64::from_le_bytes(tail));
        last.mix(self.length);
        // splitmix64's finaliser, so that nearby states give unrelated results.
        let mut z = last.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn mix(&mut self, word: u64) {
        self.state = (self.state ^ word).wrapping_mul(K).rotate_left(31);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn of(parts: &[&[u8]]) -> u64 {
        let mut c = Checksum::new();
        parts.iter().for_each(|p| c.update(p));
        c.finish()
    }

    #[test]
    fn depends_only_on_the_concatenation() {
        let data: Vec<u8> = (0..100u8).collect();
        let whole = of(&[&data]);
        for split in [0, 1, 3, 7, 8, 9, 50, 99, 100] {
            assert_eq!(of(&[&data[..split], &data[split..]]), whole, "split {split}");
        }
        assert_eq!(of(&[&data[..5], &data[5..6], &data[6..13], &data[13..]]), whole);
    }

    #[test]
    fn detects_flips_truncation_and_zero_padding() {
        let data: Vec<u8> = (0..64u8).collect();
        let whole = of(&[&data]);
        for byte in 0..data.len() {
            for bit in 0..8 {
                let mut flipped = data.clone();
                flipped[byte] ^= 1 << bit;
                assert_ne!(of(&[&flipped]), whole);
            }
        }
        assert_ne!(of(&[&data[..63]]), whole);
        assert_ne!(of(&[&data, &[0]]), whole);
    }
}
