//! When a starved learner and a blocked barrier are a deadlock, sans-IO (times are passed in).
//!
//! The learner waits for data the executors may not produce: they wait at the barrier for the
//! learner. That is the case after a replay server comes back empty, and it is broken by granting a
//! fresh warm-up share. It also *looks* like the case for a moment at the start of every run: the
//! learner is starved until the replay minimum is reached, and the executors report being at the
//! barrier just before their last batches reach the replay server. So both conditions must have
//! held together for [`REFILL_AFTER`] before a refill, not just each on its own.

use std::time::{Duration, Instant};

/// How long the learner must have been starved while every executor was at the barrier before a
/// refill, and the least time between refills.
pub const REFILL_AFTER: Duration = Duration::from_secs(1);

/// A starved learner repeats its notice (every 250 ms); one not heard from for this long is no
/// longer taken as starved: it died, or it lost its replay server, where a refill would not help.
pub const NOTICE_STALE_AFTER: Duration = Duration::from_millis(1500);

/// Tracks the two conditions and the last refill.
#[derive(Debug, Default, Clone)]
pub struct StarvationWatch {
    starved_since: Option<Instant>,
    last_notice: Option<Instant>,
    blocked_since: Option<Instant>,
    refilled_at: Option<Instant>,
}

impl StarvationWatch {
    /// The learner said whether it is starved.
    pub fn learner(&mut self, starved: bool, now: Instant) {
        self.starved_since = since(starved, self.fresh_starved_since(now), now);
        self.last_notice = starved.then_some(now);
    }

    /// Whether every live executor is at its allowance now.
    pub fn barrier(&mut self, all_blocked: bool, now: Instant) {
        self.blocked_since = since(all_blocked, self.blocked_since, now);
    }

    /// Whether to refill now; a true answer is recorded as a refill. The executors' block then
    /// starts over, since the refill lets them move.
    pub fn refill_due(&mut self, now: Instant) -> bool {
        let (Some(starved), Some(blocked)) = (self.fresh_starved_since(now), self.blocked_since) else {
            return false;
        };
        let together = now.saturating_duration_since(starved.max(blocked));
        let spaced = self.refilled_at.is_none_or(|at| now.saturating_duration_since(at) >= REFILL_AFTER);
        if together < REFILL_AFTER || !spaced {
            return false;
        }
        self.refilled_at = Some(now);
        self.blocked_since = None;
        true
    }

    /// Since when the learner has said it is starved, if it still says so.
    pub fn starved_since(&self, now: Instant) -> Option<Instant> {
        self.fresh_starved_since(now)
    }

    fn fresh_starved_since(&self, now: Instant) -> Option<Instant> {
        let fresh =
            self.last_notice.is_some_and(|at| now.saturating_duration_since(at) <= NOTICE_STALE_AFTER);
        self.starved_since.filter(|_| fresh)
    }
}

/// The start of a condition that holds now (kept from before), or `None`.
fn since(holds: bool, before: Option<Instant>, now: Instant) -> Option<Instant> {
    holds.then(|| before.unwrap_or(now))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(base: Instant, ms: u64) -> Instant {
        base + Duration::from_millis(ms)
    }

    #[test]
    fn a_long_starved_learner_waits_for_the_block_to_last_too() {
        // The start of a run: starved from the beginning, executors blocked only at 5 s.
        let t0 = Instant::now();
        let mut w = StarvationWatch::default();
        for ms in (0..=5000).step_by(250) {
            w.learner(true, at(t0, ms));
        }
        w.barrier(false, at(t0, 4000));
        assert!(!w.refill_due(at(t0, 4900)));
        assert_eq!(w.starved_since(at(t0, 5000)), Some(t0));
        w.barrier(true, at(t0, 5000));
        assert!(!w.refill_due(at(t0, 5100)), "blocked for 0.1 s only");
        // Their last batches arrive, the learner gets data: no refill.
        w.learner(false, at(t0, 5300));
        assert!(!w.refill_due(at(t0, 6500)));
    }

    #[test]
    fn a_lasting_deadlock_is_refilled_once_per_period() {
        let t0 = Instant::now();
        let mut w = StarvationWatch::default();
        w.barrier(true, t0);
        w.learner(true, at(t0, 200));
        assert!(!w.refill_due(at(t0, 1100)), "together for 0.9 s");
        assert!(w.refill_due(at(t0, 1200)));
        assert!(!w.refill_due(at(t0, 1300)), "just refilled");
        // Still blocked and starved after the refill (its steps were spent): again, a period later.
        w.barrier(true, at(t0, 1400));
        w.learner(true, at(t0, 1400));
        assert!(!w.refill_due(at(t0, 2300)), "the block restarted at 1.4 s");
        assert!(w.refill_due(at(t0, 2400)));
    }

    #[test]
    fn a_learner_that_stops_saying_it_is_starved_is_not() {
        // Its replay server went down (or it died): the notices stop, and so do refills.
        let t0 = Instant::now();
        let mut w = StarvationWatch::default();
        w.barrier(true, t0);
        w.learner(true, t0);
        assert!(!w.refill_due(at(t0, 1600)), "last notice 1.6 s ago");
        assert_eq!(w.starved_since(at(t0, 1600)), None);
        // Notices again: a new starvation, timed from now.
        w.learner(true, at(t0, 2000));
        assert_eq!(w.starved_since(at(t0, 2000)), Some(at(t0, 2000)));
        assert!(!w.refill_due(at(t0, 2500)));
        w.learner(true, at(t0, 2750));
        assert!(w.refill_due(at(t0, 3000)));
    }

    #[test]
    fn an_executor_moving_restarts_the_block() {
        let t0 = Instant::now();
        let mut w = StarvationWatch::default();
        w.learner(true, t0);
        w.barrier(true, t0);
        w.barrier(false, at(t0, 900));
        w.barrier(true, at(t0, 950));
        assert!(!w.refill_due(at(t0, 1500)));
        w.learner(true, at(t0, 1500));
        assert!(w.refill_due(at(t0, 1950)));
    }
}
