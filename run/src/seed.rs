//! splitmix64, the project's one seed mixer: distinct, well-mixed streams from one run seed.

/// The golden-ratio increment of splitmix64.
pub const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// splitmix64's output for state `x` (its increment applied first).
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(GOLDEN);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seed of stream `id` of a run seeded `seed` (the `id + 1`-th output of splitmix64 from `seed`).
pub fn mix_seed(seed: u64, id: u32) -> u64 {
    splitmix64(seed.wrapping_add(GOLDEN.wrapping_mul(u64::from(id))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_splitmix64s_outputs() {
        // splitmix64's published first output from state 0.
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(mix_seed(0, 0), splitmix64(0));
        assert_eq!(mix_seed(7, 1), splitmix64(7u64.wrapping_add(GOLDEN)));
        assert_ne!(mix_seed(1, 0), mix_seed(1, 1));
    }
}
