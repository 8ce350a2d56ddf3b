//! Key expressions: every topic lives under `rl/<run_id>/`, so runs sharing a zenoh network never
//! see each other's traffic, and `rl/<run_id>/**` is the whole run.
//!
//! [`Topic`] is the single source of truth: [`Topic::key`] builds a concrete key and
//! [`Topic::parse`] maps a received key back, and they are inverses. The free functions are
//! shorthands for publishers, plus the wildcards subscribers declare.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::TopicError;

/// Root segment of every key.
pub const ROOT: &str = "rl";
/// Longest run id accepted, in bytes.
pub const MAX_RUN_ID_LEN: usize = 64;

/// A run id that is safe as one key-expression chunk: non-empty, at most 64 bytes, and free of
/// `/` (chunk separator), `*` `$` `?` `#` (wildcards, DSL, selector and fragment syntax), `@`
/// (zenoh's verbatim and admin chunks), whitespace and control characters.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId(String);

impl RunId {
    /// Validates `id` as a run id.
    pub fn new(id: impl Into<String>) -> Result<RunId, TopicError> {
        let id = id.into();
        if id.is_empty() {
            return Err(TopicError::EmptyRunId);
        }
        if id.len() > MAX_RUN_ID_LEN {
            return Err(TopicError::RunIdTooLong { len: id.len(), max: MAX_RUN_ID_LEN });
        }
        let forbidden = |c: char| "/*$?#@".contains(c) || c.is_whitespace() || c.is_control();
        if let Some(ch) = id.chars().find(|c| forbidden(*c)) {
            return Err(TopicError::ForbiddenChar { run_id: id, ch });
        }
        Ok(RunId(id))
    }

    /// The id as given.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for RunId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for RunId {
    type Err = TopicError;

    fn from_str(s: &str) -> Result<RunId, TopicError> {
        RunId::new(s)
    }
}

/// The four process roles, spelled as in topic segments (`replay`, not `replay-server`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Role {
    /// The replay server (crate `replay-server`).
    Replay,
    /// The learner.
    Learner,
    /// An executor (actor); there are N of them, told apart by id.
    Executor,
    /// The parameter server (crate `param-server`).
    Param,
}

impl Role {
    /// Every role.
    pub const ALL: [Role; 4] = [Role::Replay, Role::Learner, Role::Executor, Role::Param];

    /// The topic segment, also the metric-name prefix (`learner/updates_per_s`).
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Replay => "replay",
            Role::Learner => "learner",
            Role::Executor => "executor",
            Role::Param => "param",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Role {
    type Err = TopicError;

    fn from_str(s: &str) -> Result<Role, TopicError> {
        Role::ALL.into_iter().find(|r| r.as_str() == s).ok_or_else(|| TopicError::UnknownRole(s.to_string()))
    }
}

/// One process: its role and its id within the role (executors 0..N, the singletons 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct NodeId {
    /// The role.
    pub role: Role,
    /// Id within the role.
    pub id: u32,
}

/// Every concrete topic of a run; [`crate::registry`] says who publishes or serves each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `experience/<executor_id>`: [`crate::ExperienceBatch`], executor → replay server.
    Experience {
        /// The publishing executor.
        executor_id: u32,
    },
    /// `replay/sample`: queryable; [`crate::SampleRequest`] in, [`crate::SampleReply`] out.
    ReplaySample,
    /// `replay/priorities`: [`crate::PriorityUpdate`], learner → replay server.
    ReplayPriorities,
    /// `replay/durable`: [`crate::DurableMarks`], replay server → executors.
    ReplayDurable,
    /// `replay/state` (`?k=N`): queryable; the replay server replies with a [`crate::StatsReport`] of
    /// its state and top-k priorities.
    ReplayState,
    /// `replay/cut`: queryable; the replay server replies with a [`crate::ReplayCut`], where a
    /// deterministic run resumes.
    ReplayCut,
    /// `params/weights`: queryable; the param server replies with a [`crate::WeightsSnapshot`], the
    /// newest or the `?version=V` asked for.
    ParamsWeights,
    /// `params/publish`: [`crate::WeightsSnapshot`], learner → param server.
    ParamsPublish,
    /// `params/stream`: [`crate::WeightsSnapshot`], param server → executors: every accepted version,
    /// published once (the zenoh routers fan it out to each host's executors).
    ParamsStream,
    /// `params/frozen`: queryable; the param server replies with [`crate::FrozenLevels`].
    ParamsFrozen,
    /// `control/step`: [`crate::GlobalStep`] announcements.
    ControlStep,
    /// `control/learner`: [`crate::LearnerStep`], learner → param server.
    ControlLearner,
    /// `eval`: [`crate::EvalReport`] from the learner's evaluations.
    Evaluation,
    /// `control/barrier/<executor_id>`: [`crate::BarrierReport`] from one executor.
    ControlBarrier {
        /// The reporting executor.
        executor_id: u32,
    },
    /// `stats/<role>/<id>`: [`crate::StatsReport`] from one process.
    Stats(NodeId),
    /// `episodes/<executor_id>`: [`crate::EpisodeReport`] from one executor.
    Episodes {
        /// The reporting executor.
        executor_id: u32,
    },
    /// `liveliness/<role>/<id>`: a liveliness token, no payload.
    Liveliness(NodeId),
}

impl Topic {
    /// The concrete key expression of this topic in `run`.
    pub fn key(&self, run: &RunId) -> String {
        let rest = match self {
            Topic::Experience { executor_id } => format!("experience/{executor_id}"),
            Topic::ReplaySample => "replay/sample".to_string(),
            Topic::ReplayPriorities => "replay/priorities".to_string(),
            Topic::ReplayDurable => "replay/durable".to_string(),
            Topic::ReplayState => "replay/state".to_string(),
            Topic::ReplayCut => "replay/cut".to_string(),
            Topic::ParamsWeights => "params/weights".to_string(),
            Topic::ParamsPublish => "params/publish".to_string(),
            Topic::ParamsStream => "params/stream".to_string(),
            Topic::ParamsFrozen => "params/frozen".to_string(),
            Topic::ControlStep => "control/step".to_string(),
            Topic::ControlLearner => "control/learner".to_string(),
            Topic::Evaluation => "eval".to_string(),
            Topic::ControlBarrier { executor_id } => format!("control/barrier/{executor_id}"),
            Topic::Stats(node) => format!("stats/{}/{}", node.role, node.id),
            Topic::Episodes { executor_id } => format!("episodes/{executor_id}"),
            Topic::Liveliness(node) => format!("liveliness/{}/{}", node.role, node.id),
        };
        format!("{}/{rest}", prefix(run))
    }

    /// Maps a concrete key received in `run` back to its topic; the inverse of [`Topic::key`].
    pub fn parse(run: &RunId, key: &str) -> Result<Topic, TopicError> {
        let unknown = || TopicError::UnknownKey(key.to_string());
        let rest = key.strip_prefix(&prefix(run)).and_then(|r| r.strip_prefix('/')).ok_or_else(unknown)?;
        let segments: Vec<&str> = rest.split('/').collect();
        let topic = match segments.as_slice() {
            ["experience", id] => Topic::Experience { executor_id: parse_id(id)? },
            ["replay", "sample"] => Topic::ReplaySample,
            ["replay", "priorities"] => Topic::ReplayPriorities,
            ["replay", "durable"] => Topic::ReplayDurable,
            ["replay", "state"] => Topic::ReplayState,
            ["replay", "cut"] => Topic::ReplayCut,
            ["params", "weights"] => Topic::ParamsWeights,
            ["params", "publish"] => Topic::ParamsPublish,
            ["params", "stream"] => Topic::ParamsStream,
            ["params", "frozen"] => Topic::ParamsFrozen,
            ["control", "step"] => Topic::ControlStep,
            ["control", "learner"] => Topic::ControlLearner,
            ["eval"] => Topic::Evaluation,
            ["control", "barrier", id] => Topic::ControlBarrier { executor_id: parse_id(id)? },
            ["stats", role, id] => Topic::Stats(NodeId { role: role.parse()?, id: parse_id(id)? }),
            ["episodes", id] => Topic::Episodes { executor_id: parse_id(id)? },
            ["liveliness", role, id] => Topic::Liveliness(NodeId { role: role.parse()?, id: parse_id(id)? }),
            _ => return Err(unknown()),
        };
        Ok(topic)
    }
}

/// What a subscriber or queryable listens on: one topic, or every process's topic of one family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TopicSet {
    /// Exactly this topic.
    One(Topic),
    /// `experience/*`: every executor's batches.
    Experience,
    /// `control/barrier/*`: every executor's barrier reports.
    Barriers,
    /// `episodes/*`: every executor's finished episodes.
    Episodes,
    /// `liveliness/<role>/*`: the tokens of every process in a role.
    Liveliness(Role),
}

impl TopicSet {
    /// The key expression to declare in `run`.
    pub fn key(&self, run: &RunId) -> String {
        match self {
            TopicSet::One(topic) => topic.key(run),
            TopicSet::Experience => experience_all(run),
            TopicSet::Barriers => control_barrier_all(run),
            TopicSet::Episodes => episodes_all(run),
            TopicSet::Liveliness(role) => liveliness_role(run, *role),
        }
    }

    /// Whether `topic` is in the set.
    pub fn contains(&self, topic: &Topic) -> bool {
        match (self, topic) {
            (TopicSet::One(one), topic) => one == topic,
            (TopicSet::Experience, Topic::Experience { .. })
            | (TopicSet::Barriers, Topic::ControlBarrier { .. })
            | (TopicSet::Episodes, Topic::Episodes { .. }) => true,
            (TopicSet::Liveliness(role), Topic::Liveliness(node)) => node.role == *role,
            _ => false,
        }
    }
}

impl From<Topic> for TopicSet {
    fn from(topic: Topic) -> TopicSet {
        TopicSet::One(topic)
    }
}

/// Parses a canonical decimal `u32`: digits only, no leading zero except `0` itself, so that
/// every id has exactly one key.
fn parse_id(segment: &str) -> Result<u32, TopicError> {
    let bad = || TopicError::BadId(segment.to_string());
    let canonical = !segment.is_empty()
        && segment.bytes().all(|b| b.is_ascii_digit())
        && (segment == "0" || !segment.starts_with('0'));
    if !canonical {
        return Err(bad());
    }
    segment.parse().map_err(|_| bad())
}

/// `rl/<run>`: the prefix of every key of the run.
pub fn prefix(run: &RunId) -> String {
    format!("{ROOT}/{run}")
}

/// `rl/<run>/**`: everything in the run (a debugging spy).
pub fn run_all(run: &RunId) -> String {
    format!("{}/**", prefix(run))
}

/// `rl/<run>/experience/<executor_id>`: where an executor publishes its batches.
pub fn experience(run: &RunId, executor_id: u32) -> String {
    Topic::Experience { executor_id }.key(run)
}

/// `rl/<run>/experience/*`: the replay server's subscription.
pub fn experience_all(run: &RunId) -> String {
    format!("{}/experience/*", prefix(run))
}

/// `rl/<run>/replay/sample`: the replay server's sampling queryable.
pub fn replay_sample(run: &RunId) -> String {
    Topic::ReplaySample.key(run)
}

/// `rl/<run>/replay/priorities`: priority updates from the learner.
pub fn replay_priorities(run: &RunId) -> String {
    Topic::ReplayPriorities.key(run)
}

/// `rl/<run>/replay/durable`: the replay server's durable marks for executors' spools.
pub fn replay_durable(run: &RunId) -> String {
    Topic::ReplayDurable.key(run)
}

/// `rl/<run>/params/weights`: the param server's weights queryable (the newest snapshot, or one version).
pub fn params_weights(run: &RunId) -> String {
    Topic::ParamsWeights.key(run)
}

/// The selector parameter of a `params/weights` query that asks for one exact version
/// (`params/weights?version=500`); without it the newest is served.
pub const WEIGHTS_VERSION_PARAMETER: &str = "version";

/// `rl/<run>/params/frozen`: the param server's queryable of a hierarchy's frozen levels.
pub fn params_frozen(run: &RunId) -> String {
    Topic::ParamsFrozen.key(run)
}

/// `rl/<run>/params/publish`: the learner hands new weights to the param server.
pub fn params_publish(run: &RunId) -> String {
    Topic::ParamsPublish.key(run)
}

/// `rl/<run>/control/step`: global-step announcements.
pub fn control_step(run: &RunId) -> String {
    Topic::ControlStep.key(run)
}

/// `rl/<run>/control/learner`: the learner's progress, for the param server.
pub fn control_learner(run: &RunId) -> String {
    Topic::ControlLearner.key(run)
}

/// `rl/<run>/eval`: the learner's evaluation results.
pub fn evaluation(run: &RunId) -> String {
    Topic::Evaluation.key(run)
}

/// `rl/<run>/control/barrier/<executor_id>`: one executor's barrier report.
pub fn control_barrier(run: &RunId, executor_id: u32) -> String {
    Topic::ControlBarrier { executor_id }.key(run)
}

/// `rl/<run>/control/barrier/*`: every executor's barrier report.
pub fn control_barrier_all(run: &RunId) -> String {
    format!("{}/control/barrier/*", prefix(run))
}

/// `rl/<run>/stats/<role>/<id>`: one process's stats.
pub fn stats(run: &RunId, node: NodeId) -> String {
    Topic::Stats(node).key(run)
}

/// `rl/<run>/stats/<role>/*`: stats of every process in a role.
pub fn stats_role(run: &RunId, role: Role) -> String {
    format!("{}/stats/{role}/*", prefix(run))
}

/// `rl/<run>/stats/**`: all stats, for the monitor.
pub fn stats_all(run: &RunId) -> String {
    format!("{}/stats/**", prefix(run))
}

/// `rl/<run>/episodes/<executor_id>`: one executor's finished episodes.
pub fn episodes(run: &RunId, executor_id: u32) -> String {
    Topic::Episodes { executor_id }.key(run)
}

/// `rl/<run>/episodes/*`: every executor's finished episodes.
pub fn episodes_all(run: &RunId) -> String {
    format!("{}/episodes/*", prefix(run))
}

/// `rl/<run>/liveliness/<role>/<id>`: the liveliness token a process declares.
pub fn liveliness(run: &RunId, node: NodeId) -> String {
    Topic::Liveliness(node).key(run)
}

/// `rl/<run>/liveliness/<role>/*`: tokens of every process in a role (e.g. all executors).
pub fn liveliness_role(run: &RunId, role: Role) -> String {
    format!("{}/liveliness/{role}/*", prefix(run))
}

/// `rl/<run>/liveliness/**`: every token in the run.
pub fn liveliness_all(run: &RunId) -> String {
    format!("{}/liveliness/**", prefix(run))
}

/// One topic of every family (the stats and liveliness ones for every role), for tests.
#[cfg(test)]
pub(crate) fn examples() -> Vec<Topic> {
    let mut topics = vec![
        Topic::Experience { executor_id: 0 },
        Topic::ReplaySample,
        Topic::ReplayPriorities,
        Topic::ReplayDurable,
        Topic::ReplayState,
        Topic::ReplayCut,
        Topic::ParamsWeights,
        Topic::ParamsPublish,
        Topic::ParamsStream,
        Topic::ParamsFrozen,
        Topic::ControlStep,
        Topic::ControlLearner,
        Topic::Evaluation,
        Topic::ControlBarrier { executor_id: 12 },
        Topic::Episodes { executor_id: 5 },
    ];
    for role in Role::ALL {
        topics.push(Topic::Stats(NodeId { role, id: 1 }));
        topics.push(Topic::Liveliness(NodeId { role, id: 0 }));
    }
    topics
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run() -> RunId {
        RunId::new("ant-2026-01").unwrap()
    }

    #[test]
    fn run_id_rejects_key_expression_syntax() {
        assert_eq!(RunId::new(""), Err(TopicError::EmptyRunId));
        for bad in ["a/b", "a*", "**", "$*", "a?b", "a#b", "@admin", "a b", "tab\t", "nl\n", "\u{7}"] {
            assert!(matches!(RunId::new(bad), Err(TopicError::ForbiddenChar { .. })), "{bad:?} accepted");
        }
        assert!(matches!(RunId::new("x".repeat(65)), Err(TopicError::RunIdTooLong { .. })));
        assert_eq!("seed_3.v2".parse::<RunId>().map(|r| r.to_string()), Ok("seed_3.v2".to_string()));
    }

    #[test]
    fn builders_spell_the_documented_keys() {
        let r = run();
        let exec = NodeId { role: Role::Executor, id: 3 };
        assert_eq!(experience(&r, 7), "rl/ant-2026-01/experience/7");
        assert_eq!(experience_all(&r), "rl/ant-2026-01/experience/*");
        assert_eq!(replay_sample(&r), "rl/ant-2026-01/replay/sample");
        assert_eq!(replay_priorities(&r), "rl/ant-2026-01/replay/priorities");
        assert_eq!(params_weights(&r), "rl/ant-2026-01/params/weights");
        assert_eq!(params_publish(&r), "rl/ant-2026-01/params/publish");
        assert_eq!(control_step(&r), "rl/ant-2026-01/control/step");
        assert_eq!(control_learner(&r), "rl/ant-2026-01/control/learner");
        assert_eq!(evaluation(&r), "rl/ant-2026-01/eval");
        assert_eq!(control_barrier(&r, 2), "rl/ant-2026-01/control/barrier/2");
        assert_eq!(control_barrier_all(&r), "rl/ant-2026-01/control/barrier/*");
        assert_eq!(stats(&r, exec), "rl/ant-2026-01/stats/executor/3");
        assert_eq!(stats_role(&r, Role::Param), "rl/ant-2026-01/stats/param/*");
        assert_eq!(stats_all(&r), "rl/ant-2026-01/stats/**");
        assert_eq!(episodes(&r, 0), "rl/ant-2026-01/episodes/0");
        assert_eq!(episodes_all(&r), "rl/ant-2026-01/episodes/*");
        assert_eq!(liveliness(&r, exec), "rl/ant-2026-01/liveliness/executor/3");
        assert_eq!(liveliness_role(&r, Role::Executor), "rl/ant-2026-01/liveliness/executor/*");
        assert_eq!(liveliness_all(&r), "rl/ant-2026-01/liveliness/**");
        assert_eq!(run_all(&r), "rl/ant-2026-01/**");
    }

    #[test]
    fn a_topic_set_contains_what_its_key_matches() {
        let r = run();
        let cases = [
            (TopicSet::Experience, Topic::Experience { executor_id: 4 }, true),
            (TopicSet::Experience, Topic::Episodes { executor_id: 4 }, false),
            (TopicSet::Barriers, Topic::ControlBarrier { executor_id: 0 }, true),
            (TopicSet::Episodes, Topic::Episodes { executor_id: 9 }, true),
            (
                TopicSet::Liveliness(Role::Replay),
                Topic::Liveliness(NodeId { role: Role::Replay, id: 0 }),
                true,
            ),
            (
                TopicSet::Liveliness(Role::Replay),
                Topic::Liveliness(NodeId { role: Role::Param, id: 0 }),
                false,
            ),
            (TopicSet::One(Topic::ControlStep), Topic::ControlStep, true),
            (TopicSet::One(Topic::ControlStep), Topic::ControlLearner, false),
        ];
        for (set, topic, inside) in cases {
            assert_eq!(set.contains(&topic), inside, "{set:?} {topic:?}");
            // The key expression agrees: a concrete key is in the set exactly when the wildcard's
            // prefix (before `*`) starts it and it has the same number of chunks.
            let (key, pattern) = (topic.key(&r), set.key(&r));
            let stem = pattern.trim_end_matches('*');
            let same_depth = key.split('/').count() == pattern.split('/').count();
            assert_eq!(key.starts_with(stem) && same_depth, inside, "{pattern} vs {key}");
        }
    }

    #[test]
    fn parse_inverts_key_for_every_topic() {
        let r = run();
        let mut topics = examples();
        topics.push(Topic::Experience { executor_id: u32::MAX });
        for topic in topics {
            assert_eq!(Topic::parse(&r, &topic.key(&r)), Ok(topic));
        }
    }

    #[test]
    fn parse_rejects_foreign_and_non_canonical_keys() {
        let r = run();
        let other = RunId::new("other").unwrap();
        assert!(Topic::parse(&r, &experience(&other, 1)).is_err());
        assert!(Topic::parse(&r, "rl/ant-2026-01x/experience/1").is_err());
        for bad in ["experience/01", "experience/-1", "experience/+1", "experience/4294967296", "experience/"]
        {
            let key = format!("rl/ant-2026-01/{bad}");
            assert!(matches!(Topic::parse(&r, &key), Err(TopicError::BadId(_))), "{key} accepted");
        }
        assert_eq!(
            Topic::parse(&r, "rl/ant-2026-01/stats/monitor/0"),
            Err(TopicError::UnknownRole("monitor".to_string()))
        );
        assert!(matches!(Topic::parse(&r, "rl/ant-2026-01/replay/sample/x"), Err(TopicError::UnknownKey(_))));
        assert!(matches!(Topic::parse(&r, "rl/ant-2026-01/experience/*"), Err(TopicError::BadId(_))));
    }
}
