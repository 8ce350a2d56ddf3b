//! The key families the monitor subscribes to, and a counter per family: how many messages arrived
//! and how many could not be decoded, so a version mismatch or a corrupt publisher shows on screen
//! instead of as silently missing figures.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One subscription of the monitor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// `stats/**`: [`proto::StatsReport`].
    Stats,
    /// `episodes/*`: [`proto::EpisodeReport`].
    Episodes,
    /// `eval`: [`proto::EvalReport`].
    Eval,
    /// `control/step`: [`proto::GlobalStep`].
    Step,
    /// `control/barrier/*`: [`proto::BarrierReport`] (one whose executor id is not its key's counts as
    /// undecodable).
    Barrier,
    /// `liveliness/**`: tokens (a key that names no process counts as undecodable).
    Liveliness,
}

impl Family {
    /// Every family, in display order.
    pub const ALL: [Family; 6] =
        [Family::Stats, Family::Episodes, Family::Eval, Family::Step, Family::Barrier, Family::Liveliness];

    /// Short name, as on screen.
    pub fn as_str(self) -> &'static str {
        match self {
            Family::Stats => "stats",
            Family::Episodes => "episodes",
            Family::Eval => "eval",
            Family::Step => "step",
            Family::Barrier => "barrier",
            Family::Liveliness => "liveliness",
        }
    }

    fn index(self) -> usize {
        self as usize
    }

    /// The family named `name`, as [`as_str`](Self::as_str) spells it.
    pub fn from_name(name: &str) -> Option<Family> {
        Family::ALL.into_iter().find(|f| f.as_str() == name)
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A count per [`Family`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FamilyCounts {
    counts: [u64; Family::ALL.len()],
}

impl FamilyCounts {
    /// Counts one more for `family`.
    pub fn add(&mut self, family: Family) {
        self.counts[family.index()] += 1;
    }

    /// The count for `family`.
    pub fn get(&self, family: Family) -> u64 {
        self.counts[family.index()]
    }

    /// The sum over all families.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }
}

/// As a JSON object keyed by family name, every family present.
impl Serialize for FamilyCounts {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_map(Family::ALL.iter().map(|f| (f.as_str(), self.get(*f))))
    }
}

/// From a JSON object keyed by family name; families it lacks count 0, names it does not know
/// (a newer monitor's) are ignored.
impl<'de> Deserialize<'de> for FamilyCounts {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let by_name = BTreeMap::<String, u64>::deserialize(deserializer)?;
        let mut counts = FamilyCounts::default();
        for (name, n) in by_name {
            if let Some(family) = Family::from_name(&name) {
                counts.counts[family.index()] = n;
            }
        }
        Ok(counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_per_family() {
        let mut c = FamilyCounts::default();
        c.add(Family::Eval);
        c.add(Family::Eval);
        c.add(Family::Liveliness);
        assert_eq!(c.get(Family::Eval), 2);
        assert_eq!(c.get(Family::Liveliness), 1);
        assert_eq!(c.get(Family::Stats), 0);
        assert_eq!(c.total(), 3);
        assert!(Family::ALL.iter().enumerate().all(|(i, f)| f.index() == i));
    }
}
