//! What the async shell hands the rollout thread: the newest global step and the newest weights,
//! behind one mutex and a condition variable the thread sleeps on while it waits at the barrier.

use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use agent::ParamSnapshot;
use proto::GlobalStep;

/// The latest control state; the thread takes weights out, the rest it reads.
#[derive(Debug, Default)]
pub struct Control {
    /// The newest announcement (its learner step never goes back, see [`Inbox::set_step`]).
    pub step: Option<GlobalStep>,
    /// Weights newer than what the thread has loaded, waiting to be loaded.
    pub weights: Option<ParamSnapshot>,
    /// Stop requested.
    pub stop: bool,
    /// Bumped on every change, so a waiter knows whether it woke for something.
    pub generation: u64,
    /// When the last announcement arrived (changed or not): the param server's heartbeat.
    pub heard_at: Option<Instant>,
}

/// What the thread takes out of the inbox before each step.
#[derive(Debug)]
pub struct Taken {
    /// The newest announcement.
    pub step: Option<GlobalStep>,
    /// Weights to load, if new ones arrived.
    pub weights: Option<ParamSnapshot>,
    /// Stop requested.
    pub stop: bool,
    /// The generation, for [`Inbox::wait_for_change`].
    pub generation: u64,
    /// When the last announcement arrived.
    pub heard_at: Option<Instant>,
}

/// Shell → thread mailbox.
#[derive(Debug, Default)]
pub struct Inbox {
    control: Mutex<Control>,
    changed: Condvar,
}

impl Inbox {
    fn lock(&self) -> MutexGuard<'_, Control> {
        // A panicking holder leaves plain data behind; keep going with it.
        self.control.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn changed(&self, mut control: MutexGuard<'_, Control>) {
        control.generation += 1;
        drop(control);
        self.changed.notify_all();
    }

    /// A new announcement. Its learner step is kept monotone: a restarted param server announces a
    /// lower step until the learner reports again, and executors must not read that as a reset.
    pub fn set_step(&self, mut step: GlobalStep) {
        let mut control = self.lock();
        control.heard_at = Some(Instant::now());
        if let Some(old) = control.step {
            step.learner_step = step.learner_step.max(old.learner_step);
        }
        if control.step == Some(step) {
            return;
        }
        control.step = Some(step);
        self.changed(control);
    }

    /// New weights; older than ones already waiting are ignored. Returns whether they were taken.
    pub fn set_weights(&self, snapshot: ParamSnapshot) -> bool {
        let mut control = self.lock();
        if control.weights.as_ref().is_some_and(|w| w.version >= snapshot.version) {
            return false;
        }
        control.weights = Some(snapshot);
        self.changed(control);
        true
    }

    /// Asks the thread to stop.
    pub fn stop(&self) {
        let mut control = self.lock();
        control.stop = true;
        self.changed(control);
    }

    /// The current state, with the weights to load taken out.
    pub fn take(&self) -> Taken {
        let mut control = self.lock();
        let weights = control.weights.take();
        Taken {
            step: control.step,
            weights,
            stop: control.stop,
            generation: control.generation,
            heard_at: control.heard_at,
        }
    }

    /// Sleeps until something changes after `seen` or `timeout` passes.
    pub fn wait_for_change(&self, seen: u64, timeout: Duration) {
        let control = self.lock();
        let _ = self
            .changed
            .wait_timeout_while(control, timeout, |c| c.generation == seen)
            .unwrap_or_else(PoisonError::into_inner);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(learner_step: u64, share: u64) -> GlobalStep {
        GlobalStep {
            learner_step,
            weights_version: 0,
            env_steps_per_learner_step: 1,
            warm_up_share: share,
            min_weights_version: 0,
            live_executors: 1,
        }
    }

    #[test]
    fn the_step_never_goes_back_but_other_fields_follow() {
        let inbox = Inbox::default();
        inbox.set_step(step(10, 5));
        inbox.set_step(step(3, 7));
        let taken = inbox.take();
        assert_eq!(taken.step, Some(step(10, 7)));
        assert!(taken.heard_at.is_some());
    }

    #[test]
    fn only_newer_weights_wait_and_a_change_wakes_the_waiter() {
        let inbox = std::sync::Arc::new(Inbox::default());
        assert!(inbox.set_weights(ParamSnapshot { version: 5, safetensors: vec![] }));
        assert!(!inbox.set_weights(ParamSnapshot { version: 4, safetensors: vec![] }));
        let taken = inbox.take();
        assert_eq!(taken.weights.map(|w| w.version), Some(5));
        assert!(!taken.stop);
        let seen = taken.generation;
        let other = inbox.clone();
        let waiter = std::thread::spawn(move || other.wait_for_change(seen, Duration::from_secs(30)));
        inbox.stop();
        waiter.join().unwrap();
        assert!(inbox.take().stop);
    }
}
