//! An executor id's env steps over all the processes that ran under it.
//!
//! A restarted executor counts from 0 again. Its stats, barrier and episode reports each carry its
//! count and each only grows within one process, so a count that goes back is a new process: the
//! old one's steps are kept as retired. Liveliness would not do: a token also blips when a link is
//! lost under load, and a new process's first reports may arrive before its token does.

/// Which report a count came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepSource {
    /// `executor/env_steps` in its stats report.
    Stats = 0,
    /// Its barrier report.
    Barrier = 1,
    /// Its latest episode report.
    Episode = 2,
}

/// Env steps of one executor id.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct StepCount {
    /// Steps of the earlier processes under this id.
    retired: u64,
    /// The current process's latest count from each source.
    latest: [Option<u64>; 3],
}

impl StepCount {
    /// A count from `source`.
    pub fn observe(&mut self, source: StepSource, steps: u64) {
        let slot = source as usize;
        if self.latest[slot].is_some_and(|before| steps < before) {
            self.retired += self.current();
            self.latest = [None; 3];
        }
        self.latest[slot] = Some(steps);
    }

    /// The current process's steps: the largest of its sources, since whichever arrived last is the
    /// newest.
    pub fn current(&self) -> u64 {
        self.latest.iter().flatten().copied().max().unwrap_or(0)
    }

    /// Steps of every process under this id.
    pub fn total(&self) -> u64 {
        self.retired + self.current()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_that_goes_back_is_a_new_process() {
        let mut c = StepCount::default();
        c.observe(StepSource::Stats, 1000);
        c.observe(StepSource::Barrier, 1100);
        c.observe(StepSource::Episode, 1050);
        assert_eq!(c.total(), 1100);
        c.observe(StepSource::Barrier, 20);
        assert_eq!((c.current(), c.total()), (20, 1120));
        // The new process's other sources start afresh, whatever the old ones said.
        c.observe(StepSource::Stats, 10);
        c.observe(StepSource::Episode, 60);
        assert_eq!(c.total(), 1160);
    }

    #[test]
    fn sources_behind_one_another_are_the_same_process() {
        let mut c = StepCount::default();
        c.observe(StepSource::Barrier, 500);
        c.observe(StepSource::Stats, 300);
        c.observe(StepSource::Episode, 450);
        assert_eq!(c.total(), 500);
    }
}
