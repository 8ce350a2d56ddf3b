//! Axis ranges with "nice" tick steps (1, 2 or 5 times a power of ten) and short tick labels
//! (`250k`, `1.5M`, `0.25`, `2e-4`), so a 5x7 font suffices.

/// An axis: its range (padded to whole steps) and where the ticks go.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// The value at the low end.
    pub lo: f64,
    /// The value at the high end (> `lo`).
    pub hi: f64,
    /// Distance between ticks.
    pub step: f64,
}

/// About this many ticks per axis.
const TARGET_TICKS: f64 = 5.0;

impl Axis {
    /// An axis covering `min..=max` (any finite values; an empty or zero-width range is widened).
    pub fn covering(min: f64, max: f64) -> Axis {
        let (min, max) =
            if min.is_finite() && max.is_finite() && min <= max { (min, max) } else { (0.0, 1.0) };
        let (min, max) = if max - min > max.abs().max(min.abs()) * 1e-12 {
            (min, max)
        } else {
            // A flat series: a unit (or 10%) band around the value.
            let half = if min == 0.0 { 1.0 } else { min.abs() * 0.1 };
            (min - half, max + half)
        };
        let step = nice_step((max - min) / TARGET_TICKS);
        Axis { lo: (min / step).floor() * step, hi: (max / step).ceil() * step, step }
    }

    /// The tick values, low to high.
    pub fn ticks(&self) -> Vec<f64> {
        let first = (self.lo / self.step).round() as i64;
        let last = (self.hi / self.step).round() as i64;
        // Multiples of the step, not repeated addition, so 0.1 + 0.2 never shows up.
        (first..=last).map(|k| k as f64 * self.step).collect()
    }

    /// Where `value` falls, 0 at `lo` to 1 at `hi`.
    pub fn fraction(&self, value: f64) -> f64 {
        (value - self.lo) / (self.hi - self.lo)
    }

    /// The label of tick `value`.
    pub fn label(&self, value: f64) -> String {
        format_tick(value, self.step, self.lo.abs().max(self.hi.abs()))
    }
}

/// 1, 2 or 5 times a power of ten, the smallest such at least `rough`.
fn nice_step(rough: f64) -> f64 {
    let magnitude = 10f64.powf(rough.log10().floor());
    let normalized = rough / magnitude;
    let nice = if normalized <= 1.0 {
        1.0
    } else if normalized <= 2.0 {
        2.0
    } else if normalized <= 5.0 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// `value` as a tick label on an axis whose ticks are `step` apart and whose largest magnitude is
/// `extent`: thousands as `k`, millions as `M`, tiny values in `e` notation, and just enough decimals
/// to tell neighbouring ticks apart.
pub fn format_tick(value: f64, step: f64, extent: f64) -> String {
    if value.abs() < step * 1e-6 {
        return "0".to_string();
    }
    let (unit, suffix) = if extent >= 1e6 {
        (1e6, "M")
    } else if extent >= 1e3 {
        (1e3, "k")
    } else {
        (1.0, "")
    };
    let scaled_step = step / unit;
    if unit == 1.0 && scaled_step < 1e-3 {
        let digits = (value.abs().log10().floor() - step.log10().floor()).clamp(0.0, 3.0) as usize;
        return format!("{value:.digits$e}");
    }
    let decimals = (-scaled_step.log10() - 1e-9).ceil().clamp(0.0, 6.0) as usize;
    format!("{:.decimals$}{suffix}", value / unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_are_one_two_or_five_times_a_power_of_ten() {
        assert_eq!(nice_step(0.9), 1.0);
        assert_eq!(nice_step(1.3), 2.0);
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(42_000.0), 50_000.0);
        assert!((nice_step(0.013) - 0.02).abs() < 1e-15);
    }

    #[test]
    fn the_axis_covers_the_data_with_whole_steps() {
        let a = Axis::covering(3.0, 247_000.0);
        assert_eq!(a, Axis { lo: 0.0, hi: 250_000.0, step: 50_000.0 });
        assert_eq!(a.ticks(), [0.0, 50_000.0, 100_000.0, 150_000.0, 200_000.0, 250_000.0]);
        assert_eq!(a.fraction(125_000.0), 0.5);
        let neg = Axis::covering(-120.0, 35.0);
        assert!(neg.lo <= -120.0 && neg.hi >= 35.0 && neg.step == 50.0);
        // Flat or empty data still gives a usable axis.
        let flat = Axis::covering(5.0, 5.0);
        assert!(flat.lo < 5.0 && flat.hi > 5.0);
        let empty = Axis::covering(f64::INFINITY, f64::NEG_INFINITY);
        assert_eq!((empty.lo, empty.hi), (0.0, 1.0));
    }

    #[test]
    fn labels_are_short() {
        let a = Axis::covering(0.0, 250_000.0);
        let labels: Vec<String> = a.ticks().iter().map(|t| a.label(*t)).collect();
        assert_eq!(labels, ["0", "50k", "100k", "150k", "200k", "250k"]);
        assert_eq!(format_tick(12_500.0, 500.0, 20_000.0), "12.5k");
        assert_eq!(format_tick(1_500_000.0, 500_000.0, 3e6), "1.5M");
        assert_eq!(format_tick(0.25, 0.05, 0.5), "0.25");
        assert_eq!(format_tick(-200.0, 100.0, 500.0), "-200");
        assert_eq!(format_tick(2e-4, 1e-4, 5e-4), "2e-4");
        assert_eq!(format_tick(1e-17, 0.1, 1.0), "0");
    }
}
