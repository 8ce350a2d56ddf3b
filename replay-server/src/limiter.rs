//! The sampling rate limiter, sans-IO: a minimum size, then (optionally) a samples-per-insert ratio
//! with a tolerance, in the spirit of Reverb's `SampleToInsertRatio`.
//!
//! Only sampling is limited. Reverb also blocks inserts, but here executors publish and move on, and
//! holding their messages back would stall zenoh links (a blocked `Block` put closes its transport
//! after 5 s); executors are paced by the global-step barrier instead. Since inserts always proceed,
//! a blocked sample is always unblocked by further inserts, and `validate` in `config` refuses the
//! one case where the first batch after the warm-up would already need more inserts than the
//! minimum size. How far inserts run ahead of the ratio is reported, never enforced.
//!
//! Rule, with counts in transitions since the limiter's epoch (server start, or the restored
//! snapshot when the limiter configuration is unchanged):
//! `size ≥ min_size_to_sample` and, with a ratio r and tolerance t,
//! `sampled + batch ≤ r · (inserted − uncredited) + t`, where `uncredited` are the inserts that
//! only filled the buffer up to the minimum size.

use serde::{Deserialize, Serialize};

/// The limiter's settings (from [`crate::ReplayServerConfig`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LimiterConfig {
    /// No sampling below this many stored transitions.
    pub min_size_to_sample: u64,
    /// Transitions sampled per transition inserted; `None`: free-running after the minimum size.
    pub samples_per_insert: Option<f64>,
    /// Slack of the ratio, in sampled transitions.
    pub tolerance: f64,
}

/// What the limiter has counted since its epoch; saved with snapshots.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LimiterCounters {
    /// Transitions inserted.
    pub inserted: u64,
    /// Transitions sampled.
    pub sampled: u64,
    /// Inserts that earn no sampling credit: those that fill the buffer up to the minimum size.
    pub uncredited: u64,
}

/// Why a sample must wait.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Blocked {
    /// Too few transitions stored.
    BelowMinSize {
        /// Stored now.
        have: u64,
        /// Needed.
        min: u64,
    },
    /// Serving would exceed the ratio's allowance.
    RateLimited {
        /// Samples per credited insert if this request were served.
        ratio_if_served: f64,
        /// The configured ratio.
        max_ratio: f64,
        /// Inserts still needed before this request fits.
        missing_inserts: u64,
    },
    /// Deterministic mode: the schedule says the sample must wait for this.
    Lockstep(crate::lockstep::LockstepWait),
}

impl Blocked {
    /// Short name for metrics and counters: `below_min_size` or `rate_limited`.
    pub fn key(&self) -> &'static str {
        match self {
            Blocked::BelowMinSize { .. } => "below_min_size",
            Blocked::RateLimited { .. } => "rate_limited",
            Blocked::Lockstep(_) => "lockstep",
        }
    }

    /// The wire form of the reason.
    pub fn to_refusal(self) -> proto::RefusalReason {
        match self {
            Blocked::BelowMinSize { have, min } => proto::RefusalReason::BelowMinSize { have, min },
            Blocked::RateLimited { ratio_if_served, max_ratio, .. } => proto::RefusalReason::RateLimited {
                samples_per_insert: ratio_if_served,
                max_samples_per_insert: max_ratio,
            },
            // Not "for data" to the learner: the executors' barrier is the schedule's, which no
            // refill of the param server's could lift.
            Blocked::Lockstep(wait) => proto::RefusalReason::Other { detail: wait.to_string() },
        }
    }

    /// Inserts that would lift the block (for the retry hint).
    pub fn missing_inserts(&self) -> u64 {
        match *self {
            Blocked::BelowMinSize { have, min } => min.saturating_sub(have),
            Blocked::RateLimited { missing_inserts, .. } => missing_inserts,
            Blocked::Lockstep(_) => 0,
        }
    }
}

impl std::fmt::Display for Blocked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Blocked::BelowMinSize { have, min } => write!(f, "below min size {min} (have {have})"),
            Blocked::RateLimited { ratio_if_served, max_ratio, missing_inserts } => write!(
                f,
                "samples per insert would be {ratio_if_served:.2} > {max_ratio:.2}; needs {missing_inserts} more inserts"
            ),
            Blocked::Lockstep(wait) => write!(f, "{wait}"),
        }
    }
}

/// How a limiter came back from a snapshot.
#[derive(Debug, Clone, PartialEq)]
pub enum Resumed {
    /// No snapshot: a fresh epoch.
    Fresh,
    /// Same configuration as when saved: counters continue.
    Continued,
    /// The configuration changed: a new epoch, so an old debt is not imposed under new rules.
    Reset {
        /// The configuration in the snapshot.
        saved: LimiterConfig,
    },
}

/// The rate limiter: configuration plus counters.
#[derive(Debug, Clone, PartialEq)]
pub struct RateLimiter {
    cfg: LimiterConfig,
    counters: LimiterCounters,
}

impl RateLimiter {
    /// A limiter starting a fresh epoch on a buffer that holds `size` transitions.
    pub fn new(cfg: LimiterConfig, size: u64) -> Self {
        let uncredited = cfg.min_size_to_sample.saturating_sub(size);
        Self { cfg, counters: LimiterCounters { uncredited, ..LimiterCounters::default() } }
    }

    /// A limiter resuming from what a snapshot saved (if anything), on a buffer of `size`.
    pub fn resume(
        cfg: LimiterConfig,
        saved: Option<(LimiterConfig, LimiterCounters)>,
        size: u64,
    ) -> (Self, Resumed) {
        match saved {
            None => (Self::new(cfg, size), Resumed::Fresh),
            Some((old, counters)) if old == cfg => (Self { cfg, counters }, Resumed::Continued),
            Some((old, _)) => (Self::new(cfg, size), Resumed::Reset { saved: old }),
        }
    }

    /// The configuration.
    pub fn config(&self) -> LimiterConfig {
        self.cfg
    }

    /// The counters (to save with a snapshot).
    pub fn counters(&self) -> LimiterCounters {
        self.counters
    }

    /// Whether a batch of `batch` may be sampled from a buffer holding `size` now.
    pub fn check_sample(&self, size: u64, batch: u32) -> Result<(), Blocked> {
        let min = self.cfg.min_size_to_sample;
        if size < min {
            return Err(Blocked::BelowMinSize { have: size, min });
        }
        let Some(ratio) = self.cfg.samples_per_insert else { return Ok(()) };
        let credited = self.credited_inserts();
        let wanted = self.counters.sampled as f64 + f64::from(batch);
        let allowed = ratio * credited as f64 + self.cfg.tolerance;
        if wanted <= allowed {
            return Ok(());
        }
        let missing = ((wanted - allowed) / ratio).ceil() as u64;
        Err(Blocked::RateLimited {
            ratio_if_served: wanted / credited.max(1) as f64,
            max_ratio: ratio,
            missing_inserts: missing.max(1),
        })
    }

    /// Transitions that may be sampled right now (ratio allowance minus what was sampled); `None`
    /// when free-running. Negative means sampling is ahead of the ratio.
    pub fn sample_allowance(&self) -> Option<f64> {
        let ratio = self.cfg.samples_per_insert?;
        Some(ratio * self.credited_inserts() as f64 + self.cfg.tolerance - self.counters.sampled as f64)
    }

    /// Samples per credited insert so far (0 before any credit).
    pub fn observed_ratio(&self) -> f64 {
        let credited = self.credited_inserts();
        if credited == 0 { 0.0 } else { self.counters.sampled as f64 / credited as f64 }
    }

    /// Counts `n` inserted transitions.
    pub fn on_insert(&mut self, n: u64) {
        self.counters.inserted += n;
    }

    /// Counts `n` sampled transitions.
    pub fn on_sample(&mut self, n: u64) {
        self.counters.sampled += n;
    }

    fn credited_inserts(&self) -> u64 {
        self.counters.inserted.saturating_sub(self.counters.uncredited)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FREE: LimiterConfig =
        LimiterConfig { min_size_to_sample: 100, samples_per_insert: None, tolerance: 0.0 };
    const RATIO: LimiterConfig =
        LimiterConfig { min_size_to_sample: 100, samples_per_insert: Some(4.0), tolerance: 64.0 };

    #[test]
    fn min_size_blocks_until_reached() {
        let mut l = RateLimiter::new(FREE, 0);
        assert_eq!(l.check_sample(99, 32), Err(Blocked::BelowMinSize { have: 99, min: 100 }));
        l.on_insert(100);
        assert_eq!(l.check_sample(100, 32), Ok(()));
        l.on_sample(1_000_000);
        assert_eq!(l.check_sample(100, 32), Ok(()), "free-running never rate-limits");
        assert_eq!(l.sample_allowance(), None);
    }

    #[test]
    fn ratio_allows_tolerance_then_ratio_times_inserts() {
        let mut l = RateLimiter::new(RATIO, 0);
        l.on_insert(100);
        // At the minimum size: exactly the tolerance (64) may be sampled.
        assert_eq!(l.check_sample(100, 64), Ok(()));
        l.on_sample(64);
        let blocked = l.check_sample(100, 32).unwrap_err();
        assert_eq!(blocked.missing_inserts(), 8, "32 samples / 4 per insert");
        assert_eq!(blocked.key(), "rate_limited");
        l.on_insert(7);
        assert!(l.check_sample(107, 32).is_err());
        l.on_insert(1);
        assert_eq!(l.check_sample(108, 32), Ok(()));
        assert_eq!(l.sample_allowance(), Some(32.0));
        l.on_sample(32);
        assert_eq!(l.observed_ratio(), 12.0);
    }

    #[test]
    fn uncredited_inserts_follow_the_starting_size() {
        // A buffer already holding 60 of the 100 needed: only 40 inserts are uncredited.
        let mut l = RateLimiter::new(RATIO, 60);
        assert_eq!(l.counters().uncredited, 40);
        l.on_insert(50);
        assert_eq!(l.sample_allowance(), Some(4.0 * 10.0 + 64.0));
    }

    #[test]
    fn resume_continues_only_under_the_same_config() {
        let mut l = RateLimiter::new(RATIO, 0);
        l.on_insert(200);
        l.on_sample(300);
        let saved = Some((l.config(), l.counters()));
        let (same, how) = RateLimiter::resume(RATIO, saved, 200);
        assert_eq!((same.counters(), how), (l.counters(), Resumed::Continued));
        let changed = LimiterConfig { samples_per_insert: Some(8.0), ..RATIO };
        let (fresh, how) = RateLimiter::resume(changed, saved, 200);
        assert_eq!(how, Resumed::Reset { saved: RATIO });
        assert_eq!(fresh.counters(), LimiterCounters::default());
        assert_eq!(RateLimiter::resume(RATIO, None, 0).1, Resumed::Fresh);
    }

    #[test]
    fn refusal_reasons_are_finite_and_readable() {
        let mut l = RateLimiter::new(RATIO, 0);
        l.on_insert(100);
        l.on_sample(64);
        let blocked = l.check_sample(100, 64).unwrap_err();
        assert_eq!(blocked.to_string(), "samples per insert would be 128.00 > 4.00; needs 16 more inserts");
        match blocked.to_refusal() {
            proto::RefusalReason::RateLimited { samples_per_insert, max_samples_per_insert } => {
                assert!(samples_per_insert.is_finite());
                assert_eq!(max_samples_per_insert, 4.0);
            }
            other => panic!("unexpected {other:?}"),
        }
    }
}
