//! Message faults a test can put on one process's bus, per topic (as raft-rs's test network drops and
//! delays messages between nodes): every typed send and receive of [`crate::Bus`] asks [`Faults`]
//! what to do with the message. Sans-IO: the rules and their verdicts; the bus applies them.
//!
//! A process's faults start empty and cost one atomic load per message while they are; only tests
//! install rules (the cluster harness hands out each role's [`Faults`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use proto::Topic;

/// Which way a message crosses this process's bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Published, or a query sent.
    Out,
    /// Received by a subscriber or queryable.
    In,
}

/// What happens to a matching message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// Lost: never sent or never delivered (a query sent is answered by silence after its timeout).
    Drop,
    /// Held this long before it goes on; later messages of the same subscriber wait behind it, as on a
    /// slow link.
    Delay(Duration),
}

/// What the bus does with one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Send or deliver it now.
    Pass,
    /// Lose it.
    Drop,
    /// Hold it this long first.
    Delay(Duration),
}

/// A rule's handle, for [`Faults::heal`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RuleId(u64);

type Matcher = Arc<dyn Fn(&Topic) -> bool + Send + Sync>;

struct Rule {
    id: RuleId,
    direction: Direction,
    matches: Matcher,
    fault: Fault,
    /// Messages it still applies to; `None`: until healed.
    remaining: Option<u64>,
}

#[derive(Default)]
struct Table {
    rules: Vec<Rule>,
    next_id: u64,
}

/// The fault rules of one process's bus; clones share them.
#[derive(Clone, Default)]
pub struct Faults {
    table: Arc<Mutex<Table>>,
    /// Whether any rule is installed: the fast path of every message.
    active: Arc<AtomicBool>,
    dropped: Arc<AtomicU64>,
    delayed: Arc<AtomicU64>,
}

impl std::fmt::Debug for Faults {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Faults")
            .field("rules", &self.lock().rules.len())
            .field("dropped", &self.dropped())
            .field("delayed", &self.delayed())
            .finish()
    }
}

impl Faults {
    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        self.table.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Applies `fault` to the next `times` messages going `direction` whose topic `matches` (all of
    /// them until healed when `times` is `None`). The first installed rule that matches decides.
    pub fn add(
        &self,
        direction: Direction,
        matches: impl Fn(&Topic) -> bool + Send + Sync + 'static,
        fault: Fault,
        times: Option<u64>,
    ) -> RuleId {
        let mut table = self.lock();
        let id = RuleId(table.next_id);
        table.next_id += 1;
        table.rules.push(Rule { id, direction, matches: Arc::new(matches), fault, remaining: times });
        self.active.store(true, Ordering::Release);
        id
    }

    /// Loses the next `n` matching messages going `direction`.
    pub fn drop_next(
        &self,
        direction: Direction,
        matches: impl Fn(&Topic) -> bool + Send + Sync + 'static,
        n: u64,
    ) -> RuleId {
        self.add(direction, matches, Fault::Drop, Some(n))
    }

    /// Loses every matching message going `direction` until healed: a cut link.
    pub fn cut(
        &self,
        direction: Direction,
        matches: impl Fn(&Topic) -> bool + Send + Sync + 'static,
    ) -> RuleId {
        self.add(direction, matches, Fault::Drop, None)
    }

    /// Holds every matching message going `direction` for `by` until healed.
    pub fn delay(
        &self,
        direction: Direction,
        matches: impl Fn(&Topic) -> bool + Send + Sync + 'static,
        by: Duration,
    ) -> RuleId {
        self.add(direction, matches, Fault::Delay(by), None)
    }

    /// Removes a rule (a no-op if it ran out or was removed).
    pub fn heal(&self, id: RuleId) {
        let mut table = self.lock();
        table.rules.retain(|r| r.id != id);
        self.active.store(!table.rules.is_empty(), Ordering::Release);
    }

    /// Removes every rule.
    pub fn heal_all(&self) {
        self.lock().rules.clear();
        self.active.store(false, Ordering::Release);
    }

    /// Messages lost to a rule so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Messages held by a rule so far.
    pub fn delayed(&self) -> u64 {
        self.delayed.load(Ordering::Relaxed)
    }

    /// What to do with a message on `topic` going `direction`; `topic` is only computed (a key parse)
    /// when some rule is installed.
    pub fn verdict(&self, direction: Direction, topic: impl FnOnce() -> Option<Topic>) -> Verdict {
        if !self.active.load(Ordering::Acquire) {
            return Verdict::Pass;
        }
        let Some(topic) = topic() else { return Verdict::Pass };
        let mut table = self.lock();
        let Some(at) = table.rules.iter().position(|r| r.direction == direction && (r.matches)(&topic))
        else {
            return Verdict::Pass;
        };
        let rule = &mut table.rules[at];
        let fault = rule.fault;
        if let Some(remaining) = &mut rule.remaining {
            *remaining -= 1;
            if *remaining == 0 {
                table.rules.remove(at);
                self.active.store(!table.rules.is_empty(), Ordering::Release);
            }
        }
        match fault {
            Fault::Drop => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                Verdict::Drop
            }
            Fault::Delay(by) => {
                self.delayed.fetch_add(1, Ordering::Relaxed);
                Verdict::Delay(by)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step() -> Option<Topic> {
        Some(Topic::ControlStep)
    }

    #[test]
    fn without_rules_everything_passes_and_no_topic_is_computed() {
        let faults = Faults::default();
        assert_eq!(faults.verdict(Direction::Out, || panic!("parsed a key with no rules")), Verdict::Pass);
    }

    #[test]
    fn drop_next_loses_exactly_n_matching_messages_in_its_direction() {
        let faults = Faults::default();
        faults.drop_next(Direction::In, |t| matches!(t, Topic::ControlStep), 2);
        assert_eq!(faults.verdict(Direction::Out, step), Verdict::Pass, "other direction");
        assert_eq!(
            faults.verdict(Direction::In, || Some(Topic::ParamsWeights)),
            Verdict::Pass,
            "other topic"
        );
        assert_eq!(faults.verdict(Direction::In, step), Verdict::Drop);
        assert_eq!(faults.verdict(Direction::In, step), Verdict::Drop);
        assert_eq!(faults.verdict(Direction::In, step), Verdict::Pass, "the rule ran out");
        assert_eq!(faults.dropped(), 2);
        assert_eq!(faults.verdict(Direction::In, || panic!("no rule is left")), Verdict::Pass);
    }

    #[test]
    fn a_cut_lasts_until_healed_and_the_first_matching_rule_decides() {
        let faults = Faults::default();
        let by = Duration::from_millis(30);
        let cut = faults.cut(Direction::Out, |t| matches!(t, Topic::Experience { executor_id: 1 }));
        faults.delay(Direction::Out, |t| matches!(t, Topic::Experience { .. }), by);
        let one = || Some(Topic::Experience { executor_id: 1 });
        let two = || Some(Topic::Experience { executor_id: 2 });
        for _ in 0..5 {
            assert_eq!(faults.verdict(Direction::Out, one), Verdict::Drop);
        }
        assert_eq!(faults.verdict(Direction::Out, two), Verdict::Delay(by));
        faults.heal(cut);
        assert_eq!(faults.verdict(Direction::Out, one), Verdict::Delay(by));
        faults.heal_all();
        assert_eq!(faults.verdict(Direction::Out, one), Verdict::Pass);
        assert_eq!((faults.dropped(), faults.delayed()), (5, 2));
    }

    #[test]
    fn an_unparsable_key_passes() {
        let faults = Faults::default();
        faults.cut(Direction::In, |_| true);
        assert_eq!(faults.verdict(Direction::In, || None), Verdict::Pass);
    }
}
