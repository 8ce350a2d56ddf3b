//! A plausibility bound on the learner's step, sans-IO: global steps never go back, so one forged
//! `LearnerStep` (or weights frame) with step 2^62 would pin the barrier for the rest of the run.
//! A step may move forward by at most `max_steps_per_s` times the seconds since the last step taken
//! (at least one second's worth): the fused learner makes ~1,000-2,000 updates/s on this machine, the
//! default bound is 100,000/s, so no real learner comes near it and a forged jump is refused, counted
//! and logged while the real learner goes on. The first step after start is taken as it comes (a
//! learner resuming from a checkpoint starts far from 0); authenticating peers is what closes that.

use std::time::Instant;

/// Default bound on learner steps per second.
pub const DEFAULT_MAX_LEARNER_STEPS_PER_S: u64 = 100_000;

/// A step that moves further than the bound allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Implausible {
    /// The step offered.
    pub step: u64,
    /// The step last taken.
    pub held: u64,
    /// How far it could have moved.
    pub allowance: u64,
}

/// The last step taken and when.
#[derive(Debug, Clone)]
pub struct StepGuard {
    max_steps_per_s: u64,
    last: Option<(u64, Instant)>,
}

impl Default for StepGuard {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_LEARNER_STEPS_PER_S)
    }
}

impl StepGuard {
    /// A guard allowing `max_steps_per_s` learner steps per second.
    pub fn new(max_steps_per_s: u64) -> Self {
        Self { max_steps_per_s, last: None }
    }

    /// Whether `step`, seen at `now`, may be taken; a taken step that moves forward becomes the
    /// reference for the next one. Steps at or below the held one are taken (the barrier ignores them).
    pub fn check(&mut self, step: u64, now: Instant) -> Result<(), Implausible> {
        let Some((held, at)) = self.last else {
            self.last = Some((step, now));
            return Ok(());
        };
        if step <= held {
            return Ok(());
        }
        let seconds = now.saturating_duration_since(at).as_secs_f64().max(1.0);
        let allowance = (self.max_steps_per_s as f64 * seconds).min(u64::MAX as f64) as u64;
        if step - held > allowance {
            return Err(Implausible { step, held, allowance });
        }
        self.last = Some((step, now));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn a_forged_jump_is_refused_and_the_real_learner_goes_on() {
        let t0 = Instant::now();
        let mut g = StepGuard::new(1000);
        assert_eq!(g.check(800_000, t0), Ok(()), "the first step is taken as it comes");
        assert_eq!(g.check(800_500, t0), Ok(()), "within one second's worth");
        let forged = g.check(1 << 62, t0 + Duration::from_millis(10));
        assert_eq!(forged, Err(Implausible { step: 1 << 62, held: 800_500, allowance: 1000 }));
        assert_eq!(g.check(801_400, t0 + Duration::from_millis(20)), Ok(()), "the real learner goes on");
        assert_eq!(g.check(700, t0), Ok(()), "older steps are the barrier's to ignore");
        // A learner silent for 10 s may move 10 s worth, not more.
        let later = t0 + Duration::from_millis(20) + Duration::from_secs(10);
        assert!(g.check(801_400 + 10_001, later).is_err());
        assert_eq!(g.check(801_400 + 10_000, later), Ok(()));
    }
}
