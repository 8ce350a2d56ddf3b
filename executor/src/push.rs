//! [`PushTracker`]: which weights the weights task takes and when it asks the param server, sans-IO.
//!
//! Rules: a pushed frame is taken once an announcement names its version (or a newer one), so a
//! frame nobody announced is never used; the latest push takes the one waiting place whatever its
//! version (the param server pushes in order, so a frame nobody will announce holds it only until
//! the next push). The task asks when it holds nothing (joining: pushes only carry later versions),
//! when an announced newer version has not come by push within the grace, or at once when there is
//! no push; a failed ask is retried after `retry`.

use std::time::Duration;

use proto::WeightsSnapshot;
use tokio::time::Instant;

/// The tracker's state.
#[derive(Debug)]
pub(crate) struct PushTracker {
    /// Whether pushes can come at all.
    push: bool,
    grace: Duration,
    retry: Duration,
    /// The version handed on last.
    held: Option<u64>,
    /// The newest version announced.
    newest: Option<u64>,
    /// A pushed frame whose version no announcement has named yet.
    waiting: Option<WeightsSnapshot>,
    /// When to ask, while behind.
    ask_at: Option<Instant>,
}

impl PushTracker {
    pub(crate) fn new(push: bool, grace: Duration, retry: Duration) -> Self {
        Self { push, grace, retry, held: None, newest: None, waiting: None, ask_at: None }
    }

    /// No more pushes will come (the subscription closed): ask for every version from now on.
    pub(crate) fn push_closed(&mut self, now: Instant) {
        self.push = false;
        self.ask_at = None;
        self.schedule(now);
    }

    /// Whether `version` is newer than the one held.
    pub(crate) fn wants(&self, version: u64) -> bool {
        self.held.is_none_or(|have| version > have)
    }

    /// An announcement named `newest` as the newest version. Returns the waiting pushed frame when
    /// it is now announced and wanted: the caller takes it (and says so with [`PushTracker::took`]).
    pub(crate) fn announced(&mut self, newest: Option<u64>, now: Instant) -> Option<WeightsSnapshot> {
        self.newest = newest.max(self.newest);
        let ready = self.waiting.take_if(|f| self.newest.is_some_and(|n| n >= f.version));
        let ready = ready.filter(|f| self.wants(f.version));
        if ready.is_none() {
            self.schedule(now);
        }
        ready
    }

    /// A frame came by push.
    pub(crate) fn pushed(&mut self, frame: WeightsSnapshot, now: Instant) -> Option<WeightsSnapshot> {
        if self.wants(frame.version) {
            self.waiting = Some(frame);
        }
        // Already announced (the push came after its announcement): take it now.
        self.announced(self.newest, now)
    }

    /// `version` was handed on.
    pub(crate) fn took(&mut self, version: u64, now: Instant) {
        self.held = Some(version).max(self.held);
        self.ask_at = None;
        self.schedule(now);
    }

    /// An ask brought nothing usable: try again after the retry interval.
    pub(crate) fn ask_failed(&mut self, now: Instant) {
        self.ask_at = Some(now + self.retry);
    }

    /// Whether to ask the param server now.
    pub(crate) fn ask_due(&self, now: Instant) -> bool {
        self.ask_at.is_some_and(|at| now >= at)
    }

    /// When the next ask is due, if one is.
    pub(crate) fn ask_at(&self) -> Option<Instant> {
        self.ask_at
    }

    fn behind(&self) -> bool {
        match (self.newest, self.held) {
            (_, None) => true,
            (Some(version), Some(have)) => version > have,
            (None, Some(_)) => false,
        }
    }

    /// Sets when to ask: nothing while up to date; a deadline already set is kept.
    fn schedule(&mut self, now: Instant) {
        if !self.behind() {
            self.ask_at = None;
        } else if self.ask_at.is_none() {
            let grace = if self.held.is_none() || !self.push { Duration::ZERO } else { self.grace };
            self.ask_at = Some(now + grace);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GRACE: Duration = Duration::from_secs(1);
    const RETRY: Duration = Duration::from_millis(500);

    fn frame(version: u64) -> WeightsSnapshot {
        WeightsSnapshot { version, learner_step: version, safetensors: vec![], stack: None }
    }

    fn tracker(push: bool) -> (PushTracker, Instant) {
        (PushTracker::new(push, GRACE, RETRY), Instant::now())
    }

    #[test]
    fn a_joiner_asks_at_once_and_retries_a_failed_ask() {
        let (mut t, now) = tracker(true);
        assert!(t.announced(None, now).is_none());
        assert!(t.ask_due(now), "nothing held: ask, pushes only carry later versions");
        t.ask_failed(now);
        assert!(!t.ask_due(now + RETRY / 2));
        assert!(t.ask_due(now + RETRY));
        t.took(500, now);
        assert_eq!(t.ask_at(), None, "up to date with no announcement");
    }

    #[test]
    fn a_push_is_taken_at_its_announcement_without_asking() {
        let (mut t, now) = tracker(true);
        t.took(500, now);
        assert!(t.pushed(frame(1000), now).is_none(), "not announced yet");
        assert_eq!(t.announced(Some(1000), now).map(|f| f.version), Some(1000));
        t.took(1000, now);
        assert_eq!(t.ask_at(), None);
        // The announcement first, then the push: taken when it comes, before the grace.
        assert!(t.announced(Some(1500), now).is_none());
        assert!(!t.ask_due(now));
        assert_eq!(t.pushed(frame(1500), now).map(|f| f.version), Some(1500));
    }

    #[test]
    fn a_push_that_does_not_come_is_asked_for_after_the_grace() {
        let (mut t, now) = tracker(true);
        t.took(500, now);
        assert!(t.announced(Some(1000), now).is_none());
        assert!(!t.ask_due(now + GRACE / 2));
        assert!(t.ask_due(now + GRACE));
        // Later announcements while behind keep the first deadline.
        assert!(t.announced(Some(1500), now + GRACE / 2).is_none());
        assert_eq!(t.ask_at(), Some(now + GRACE));
    }

    #[test]
    fn without_a_push_every_version_is_asked_for_at_once() {
        let (mut t, now) = tracker(false);
        t.took(500, now);
        assert!(t.announced(Some(1000), now).is_none());
        assert!(t.ask_due(now));
        let (mut t, now) = tracker(true);
        t.took(500, now);
        t.announced(Some(1000), now);
        t.push_closed(now + GRACE / 4);
        assert!(t.ask_due(now + GRACE / 4), "a closed push asks at once");
    }

    #[test]
    fn an_unannounced_frame_is_never_taken_and_the_next_push_displaces_it() {
        let (mut t, now) = tracker(true);
        t.took(500, now);
        // A forged frame far ahead of anything announced.
        assert!(t.pushed(frame(1 << 40), now).is_none());
        assert!(t.announced(Some(1000), now).is_none(), "never taken: nobody announced it");
        assert_eq!(t.pushed(frame(1000), now).map(|f| f.version), Some(1000));
        // Old or repeated frames are not taken.
        t.took(1000, now);
        assert!(t.pushed(frame(1000), now).is_none());
        assert!(t.pushed(frame(500), now).is_none());
        assert!(!t.wants(1000) && t.wants(1001));
    }
}
