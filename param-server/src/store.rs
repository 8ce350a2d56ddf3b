//! The latest weights, sans-IO: what the param server republishes and serves on its queryable.

use proto::WeightsSnapshot;

/// Why a snapshot was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejected {
    /// The version held, sent again: the learner re-sends its newest weights whenever a param
    /// server starts listening, so this is expected, not bad input.
    Repeated {
        /// The version.
        version: u64,
    },
    /// Its version is older than the one held (a late publish, or a learner resumed from an
    /// older checkpoint).
    NotNewer {
        /// The snapshot's version.
        version: u64,
        /// The version held.
        held: u64,
    },
}

/// How many snapshots a [`ParamStore`] took and refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoreCounts {
    /// Snapshots that became the latest.
    pub accepted: u64,
    /// Snapshots refused as not newer.
    pub rejected: u64,
}

/// Holds the newest weights snapshot; versions (global steps) only move forward.
#[derive(Debug, Default, Clone)]
pub struct ParamStore {
    latest: Option<WeightsSnapshot>,
    accepted: u64,
    rejected: u64,
}

impl ParamStore {
    /// Whether a snapshot of `version` would become the latest (nothing held, or newer).
    pub fn takes(&self, version: u64) -> bool {
        self.latest.as_ref().is_none_or(|held| version > held.version)
    }

    /// Takes `snapshot` if it is newer than the one held; refusals are counted either way.
    pub fn offer(&mut self, snapshot: WeightsSnapshot) -> Result<u64, Rejected> {
        if !self.takes(snapshot.version)
            && let Some(held) = &self.latest
        {
            self.rejected += 1;
            if snapshot.version == held.version {
                return Err(Rejected::Repeated { version: held.version });
            }
            return Err(Rejected::NotNewer { version: snapshot.version, held: held.version });
        }
        self.accepted += 1;
        let version = snapshot.version;
        self.latest = Some(snapshot);
        Ok(version)
    }

    /// The newest snapshot, if any has arrived.
    pub fn latest(&self) -> Option<&WeightsSnapshot> {
        self.latest.as_ref()
    }

    /// Snapshots taken and refused so far.
    pub fn counts(&self) -> StoreCounts {
        StoreCounts { accepted: self.accepted, rejected: self.rejected }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snapshot(version: u64) -> WeightsSnapshot {
        WeightsSnapshot { version, learner_step: version, safetensors: vec![version as u8; 4], stack: None }
    }

    #[test]
    fn only_newer_versions_replace_the_latest() {
        let mut store = ParamStore::default();
        assert!(store.latest().is_none());
        assert_eq!(store.offer(snapshot(10)), Ok(10));
        assert_eq!(store.offer(snapshot(5)), Err(Rejected::NotNewer { version: 5, held: 10 }));
        assert_eq!(store.offer(snapshot(10)), Err(Rejected::Repeated { version: 10 }));
        assert_eq!(store.offer(snapshot(20)), Ok(20));
        assert_eq!(store.latest().map(|s| s.version), Some(20));
        assert_eq!(store.counts(), StoreCounts { accepted: 2, rejected: 2 });
    }
}
