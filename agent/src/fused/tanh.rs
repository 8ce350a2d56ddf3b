//! tanh for the fused learner's coupling nets: the platform's libm `tanhf` (what candle calls, so
//! results are bit-identical to the candle learner), or a branch-free version that vectorises,
//! within 1.3 ulp of the exact value (libm's own `tanhf` is within about 1.4). With libm, tanh is
//! ~10% of a fused update: every coupling net's hidden layer evaluates it per element.
//!
//! The squash a = tanh(y) always uses libm: log pi subtracts log(1 - a^2 + 1e-6), which is
//! ill-conditioned where |a| rounds to ~1 (one ulp of a moves it by up to ~0.1), so only the same
//! tanh as candle's keeps log pi, and through it V's target and the policy's advantage, equal.

/// Which tanh the fused kernels evaluate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tanh {
    /// `f32::tanh` (libm `tanhf`), as candle: bit-identical updates.
    Libm,
    /// [`fast_tanh`]: vectorised, <= 1.3 ulp (coupling nets only; see the module doc).
    Fast,
}

/// Below this |x| the odd Taylor series is used, above it 1 - 2 / (e^{2|x|} + 1): the split keeps
/// both within 1.3 ulp (the series' 8 terms converge fast enough, the subtraction loses little).
const SERIES_BELOW: f32 = 0.625;

/// Taylor coefficients of tanh(x) = x + x^3 sum_k c_k x^{2k}: -1/3, 2/15, -17/315, ...
const SERIES: [f32; 8] = [
    -1.0 / 3.0,
    2.0 / 15.0,
    -17.0 / 315.0,
    62.0 / 2835.0,
    -1382.0 / 155_925.0,
    21844.0 / 6_081_075.0,
    -929_569.0 / 638_512_875.0,
    6_404_582.0 / 10_854_718_875.0,
];

/// e^v for 0 <= v <= 20 without branches: v = k ln 2 + r, |r| <= ln 2 / 2, e^r by its degree-7
/// Taylor polynomial, 2^k from the exponent bits.
#[inline(always)]
fn exp_small_range(v: f32) -> f32 {
    // ln 2 split: the high part has 16 significant bits, so k * LN2_HI is exact (Cody-Waite).
    const LN2_HI: f32 = f32::from_bits(0x3f31_7200);
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding and subtracting 1.5 * 2^23 rounds to the nearest integer (|v / ln 2| < 2^22).
    const ROUND: f32 = 12_582_912.0;
    let k = (v * std::f32::consts::LOG2_E + ROUND) - ROUND;
    let r = (v - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 5040.0;
    for c in [1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
        p = p * r + c;
    }
    // 0 <= k <= 29 here, so the biased exponent is a normal one.
    p * f32::from_bits(((k as i32 + 127) as u32) << 23)
}

/// tanh(x) within 1.3 ulp, branch-free so loops over it vectorise; NaN propagates.
#[inline(always)]
pub(crate) fn fast_tanh(x: f32) -> f32 {
    let a = x.abs();
    let a2 = a * a;
    let mut p = SERIES[7];
    for c in SERIES[..7].iter().rev() {
        p = p * a2 + c;
    }
    let series = a + a * (a2 * p);
    // tanh(10) rounds to 1 in f32; clamping keeps e^{2|x|} finite.
    let e = exp_small_range(2.0 * a.min(10.0));
    let from_exp = 1.0 - 2.0 / (e + 1.0);
    // NaN fails the comparison and takes the series branch, which keeps it NaN.
    let t = if a >= SERIES_BELOW { from_exp } else { series };
    t.copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// |got - exact| in units of the last place of the f32 nearest the exact value.
    fn ulps(got: f32, exact: f64) -> f64 {
        let nearest = exact as f32;
        let ulp = f64::from(f32::from_bits(nearest.abs().to_bits() + 1)) - f64::from(nearest.abs());
        (f64::from(got) - exact).abs() / ulp
    }

    #[test]
    fn fast_tanh_is_within_1_3_ulp_everywhere() {
        let mut worst = (0.0, 0.0f32);
        let grid = (-400_000..=400_000).map(|i| i as f32 * 3e-5);
        let tiny = (0..2000).map(|i| 1e-9f32 * 1.02f32.powi(i));
        for x in grid.chain(tiny).chain([0.0, -0.0, 8.99, 9.5, 1e3, f32::MAX, f32::MIN_POSITIVE]) {
            let e = ulps(fast_tanh(x), f64::from(x).tanh());
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 <= 1.3, "{} ulp at x = {}", worst.0, worst.1);
        assert_eq!(fast_tanh(f32::INFINITY), 1.0);
        assert_eq!(fast_tanh(f32::NEG_INFINITY), -1.0);
        assert!(fast_tanh(f32::NAN).is_nan());
        assert!(fast_tanh(-0.0).is_sign_negative());
    }
}
