//! The importance-sampling exponent β, annealed linearly over learner steps.
//!
//! The paper's code computed the per-epoch increment as `0.6 / n_epochs + 1` (operator precedence)
//! and so jumped from 0.4 to about 1.4 after the first epoch (`docs/sac-lsp.md` §8). Here β is a pure
//! function of the learner step, clamped so that it never passes `end`.

/// Linear β schedule: `start` at step 0, `end` at `anneal_steps` and after.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BetaSchedule {
    /// β at learner step 0.
    pub start: f64,
    /// β from `anneal_steps` on.
    pub end: f64,
    /// Learner steps over which β moves from `start` to `end` (0: `end` at once).
    pub anneal_steps: u64,
}

impl BetaSchedule {
    /// β at `learner_step`: `start + (end − start) · step / anneal_steps` before the end, exactly
    /// `end` at and after it, never outside [start, end].
    pub fn beta(&self, learner_step: u64) -> f64 {
        if learner_step >= self.anneal_steps {
            return self.end;
        }
        let fraction = learner_step as f64 / self.anneal_steps as f64;
        (self.start + (self.end - self.start) * fraction).clamp(self.start, self.end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAPER: BetaSchedule = BetaSchedule { start: 0.4, end: 1.0, anneal_steps: 10_000_000 };

    #[test]
    fn starts_at_start_and_is_linear() {
        assert_eq!(PAPER.beta(0), 0.4);
        assert!((PAPER.beta(2_500_000) - 0.55).abs() < 1e-15);
        assert!((PAPER.beta(5_000_000) - 0.7).abs() < 1e-15);
        // Equal steps give equal increments.
        let d1 = PAPER.beta(1_000_000) - PAPER.beta(0);
        let d2 = PAPER.beta(9_000_000) - PAPER.beta(8_000_000);
        assert!((d1 - d2).abs() < 1e-12 && (d1 - 0.06).abs() < 1e-12);
    }

    #[test]
    fn exactly_end_at_and_after_the_end_and_never_above() {
        assert_eq!(PAPER.beta(10_000_000), 1.0);
        assert_eq!(PAPER.beta(10_000_001), 1.0);
        assert_eq!(PAPER.beta(u64::MAX), 1.0);
        assert!(PAPER.beta(9_999_999) < 1.0);
        let mut previous = 0.0;
        for step in (0..=12_000_000).step_by(7_919) {
            let beta = PAPER.beta(step);
            assert!((0.4..=1.0).contains(&beta) && beta >= previous, "step {step}: {beta}");
            previous = beta;
        }
    }

    #[test]
    fn zero_anneal_steps_means_end_at_once() {
        let s = BetaSchedule { anneal_steps: 0, ..PAPER };
        assert_eq!(s.beta(0), 1.0);
    }
}
