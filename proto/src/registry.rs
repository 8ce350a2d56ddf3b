//! Who may publish or serve each topic: the one table from which the docs' key table
//! (`docs/distributed.md`) and the access control of authenticated runs (`deploy/certs.sh`) are
//! generated. `proto/tests/registry.rs` fails when either file drifts from it, and rewrites both
//! with `SACLSP_BLESS=1`.

use crate::Role;

/// How a topic is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Published (`put`) and subscribed to.
    Publication,
    /// A queryable: one side declares it and replies, the other queries.
    Queryable,
    /// A zenoh liveliness token.
    Token,
}

/// Who writes a topic: publishes it, replies to its queries, or holds its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Writer {
    /// This role only.
    Role(Role),
    /// Every role, each under its own role's segment (`stats/<role>/<id>`).
    Own,
}

/// One topic family of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entry {
    /// The key under `rl/<run>/`, ids as `<name>` (`experience/<executor_id>`).
    pub key: &'static str,
    /// What travels on it.
    pub kind: Kind,
    /// The message type(s), as the docs name them.
    pub message: &'static str,
    /// Who writes it.
    pub writer: Writer,
    /// Only this role may query it (queryables only; `None`: any member).
    pub querier: Option<Role>,
    /// Who reads it, in words (for the docs).
    pub readers: &'static str,
}

/// Every topic family of a run, in the docs' order.
pub const TOPICS: &[Entry] = &[
    Entry {
        key: "experience/<executor_id>",
        kind: Kind::Publication,
        message: "`ExperienceBatch`",
        writer: Writer::Role(Role::Executor),
        querier: None,
        readers: "replay server (`experience/*`)",
    },
    Entry {
        key: "replay/sample",
        kind: Kind::Queryable,
        message: "`SampleRequest` → `SampleReply`",
        writer: Writer::Role(Role::Replay),
        querier: Some(Role::Learner),
        readers: "learner queries",
    },
    Entry {
        key: "replay/priorities",
        kind: Kind::Publication,
        message: "`PriorityUpdate`",
        writer: Writer::Role(Role::Learner),
        querier: None,
        readers: "replay server",
    },
    Entry {
        key: "replay/durable",
        kind: Kind::Publication,
        message: "`DurableMarks`",
        writer: Writer::Role(Role::Replay),
        querier: None,
        readers: "executors (spools)",
    },
    Entry {
        key: "replay/state",
        kind: Kind::Queryable,
        message: "`StatsReport` (state and top-k priorities, `?k=N`)",
        writer: Writer::Role(Role::Replay),
        querier: None,
        readers: "monitor queries",
    },
    Entry {
        key: "replay/cut",
        kind: Kind::Queryable,
        message: "`ReplayCut` (deterministic mode's newest cut)",
        writer: Writer::Role(Role::Replay),
        querier: None,
        readers: "learner and executors query at start",
    },
    Entry {
        key: "params/publish",
        kind: Kind::Publication,
        message: "`WeightsSnapshot`",
        writer: Writer::Role(Role::Learner),
        querier: None,
        readers: "param server",
    },
    Entry {
        key: "params/stream",
        kind: Kind::Publication,
        message: "`WeightsSnapshot` (each version once)",
        writer: Writer::Role(Role::Param),
        querier: None,
        readers: "executors (through their host's router)",
    },
    Entry {
        key: "params/weights",
        kind: Kind::Queryable,
        message: "`WeightsSnapshot` (`?version=V`)",
        writer: Writer::Role(Role::Param),
        querier: None,
        readers: "executors query when they hold none, or `control/step` names a newer version whose push has not come",
    },
    Entry {
        key: "params/frozen",
        kind: Kind::Queryable,
        message: "`FrozenLevels` (hierarchies only)",
        writer: Writer::Role(Role::Param),
        querier: None,
        readers: "executors query once",
    },
    Entry {
        key: "control/learner",
        kind: Kind::Publication,
        message: "`LearnerStep`",
        writer: Writer::Role(Role::Learner),
        querier: None,
        readers: "param server",
    },
    Entry {
        key: "control/step",
        kind: Kind::Publication,
        message: "`GlobalStep`",
        writer: Writer::Role(Role::Param),
        querier: None,
        readers: "executors, learner, monitor",
    },
    Entry {
        key: "control/barrier/<executor_id>",
        kind: Kind::Publication,
        message: "`BarrierReport`",
        writer: Writer::Role(Role::Executor),
        querier: None,
        readers: "param server, monitor",
    },
    Entry {
        key: "eval",
        kind: Kind::Publication,
        message: "`EvalReport`",
        writer: Writer::Role(Role::Learner),
        querier: None,
        readers: "monitor",
    },
    Entry {
        key: "stats/<role>/<id>",
        kind: Kind::Publication,
        message: "`StatsReport`",
        writer: Writer::Own,
        querier: None,
        readers: "monitor (`stats/**`)",
    },
    Entry {
        key: "episodes/<executor_id>",
        kind: Kind::Publication,
        message: "`EpisodeReport`",
        writer: Writer::Role(Role::Executor),
        querier: None,
        readers: "monitor (`episodes/*`)",
    },
    Entry {
        key: "liveliness/<role>/<id>",
        kind: Kind::Token,
        message: "zenoh liveliness token, no payload",
        writer: Writer::Own,
        querier: None,
        readers: "param server (executors' tokens: the barrier), executors (the replay server's: resend \
                  their spools), monitor",
    },
];

impl Entry {
    /// The key expression matching every concrete key of the family in any run (`rl/*/experience/*`).
    pub fn wildcard(&self) -> String {
        let chunks: Vec<&str> =
            self.key.split('/').map(|c| if c.starts_with('<') { "*" } else { c }).collect();
        format!("rl/*/{}", chunks.join("/"))
    }

    /// The wildcard with `role` in the role chunk, for [`Writer::Own`] families (`rl/*/stats/learner/*`).
    pub fn wildcard_of(&self, role: Role) -> String {
        let chunks: Vec<&str> =
            self.key.split('/').map(|c| if c == "<role>" { role.as_str() } else { c }).collect();
        format!("rl/*/{}", chunks.join("/").replace("<id>", "*"))
    }
}

/// The docs' key table: a Markdown table, one row per entry.
pub fn markdown_table() -> String {
    let mut out =
        String::from("| key under `rl/<run>/` | message | written by | read by |\n|---|---|---|---|\n");
    for e in TOPICS {
        let key = match e.kind {
            Kind::Queryable => format!("`{}` (queryable)", e.key),
            _ => format!("`{}`", e.key),
        };
        let writer = match (e.writer, e.kind) {
            (Writer::Own, _) => "every role, its own".to_string(),
            (Writer::Role(r), Kind::Queryable) => format!("{} replies", role_name(r)),
            (Writer::Role(r), _) => role_name(r).to_string(),
        };
        let readers = match e.querier {
            Some(r) => format!("{} (only the {} may query)", e.readers, role_name(r)),
            None => e.readers.to_string(),
        };
        out.push_str(&format!("| {key} | {} | {writer} | {readers} |\n", e.message));
    }
    out
}

fn role_name(role: Role) -> &'static str {
    match role {
        Role::Replay => "replay server",
        Role::Learner => "learner",
        Role::Executor => "executor",
        Role::Param => "param server",
    }
}

/// The roles of an authenticated run's certificates: the four, and the monitor (which only
/// listens and queries).
pub const CERT_ROLES: [&str; 5] = ["learner", "executor", "replay", "param", "monitor"];

/// The access-control rules and policies of an authenticated run (`deploy/certs.sh`), as JSON5
/// list items. Default deny; every member may do everything (`members`), except what a deny rule
/// reserves for one role: publishing or serving the topics it writes, querying what only it may
/// query, and each role's own stats and tokens. The monitor only listens and queries.
pub fn access_control() -> AccessControl {
    const PUB: &str = r#""put", "delete""#;
    const SERVE: &str = r#""declare_queryable", "reply""#;
    let mut rules = vec![
        r#"{ id: "members", permission: "allow", flows: ["ingress", "egress"], messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply", "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"], key_exprs: ["**"] },"#.to_string(),
    ];
    let mut policies = vec![format!(r#"{{ rules: ["members"], subjects: [{}] }},"#, quoted(&CERT_ROLES))];
    let mut deny = |id: String, messages: &str, keys: &[String], protected: &[&str]| {
        let keys: Vec<String> = keys.iter().map(|k| format!("\"{k}\"")).collect();
        rules.push(format!(
            r#"{{ id: "{id}", permission: "deny", flows: ["ingress"], messages: [{messages}], key_exprs: [{}] }},"#,
            keys.join(", ")
        ));
        let others: Vec<&str> = CERT_ROLES.iter().copied().filter(|r| !protected.contains(r)).collect();
        policies.push(format!(r#"{{ rules: ["{id}"], subjects: [{}] }},"#, quoted(&others)));
    };
    for role in [Role::Learner, Role::Executor, Role::Replay, Role::Param] {
        let writes = |kind: Kind| -> Vec<String> {
            TOPICS
                .iter()
                .filter(|e| e.kind == kind && e.writer == Writer::Role(role))
                .map(Entry::wildcard)
                .collect()
        };
        let name = role.as_str();
        let published = writes(Kind::Publication);
        if !published.is_empty() {
            deny(format!("{name}-publishes"), PUB, &published, &[name]);
        }
        let served = writes(Kind::Queryable);
        if !served.is_empty() {
            deny(format!("{name}-serves"), SERVE, &served, &[name]);
        }
        let queried: Vec<String> =
            TOPICS.iter().filter(|e| e.querier == Some(role)).map(Entry::wildcard).collect();
        if !queried.is_empty() {
            deny(format!("{name}-queries"), r#""query""#, &queried, &[name]);
        }
    }
    deny(
        "monitor-listens".into(),
        &format!(r#"{PUB}, {SERVE}, "liveliness_token""#),
        &["**".to_string()],
        &["learner", "executor", "replay", "param"],
    );
    for role in [Role::Learner, Role::Executor, Role::Replay, Role::Param] {
        let own: Vec<String> =
            TOPICS.iter().filter(|e| e.writer == Writer::Own).map(|e| e.wildcard_of(role)).collect();
        deny(format!("own-{role}"), &format!(r#"{PUB}, "liveliness_token""#), &own, &[role.as_str()]);
    }
    AccessControl { rules, policies }
}

/// [`access_control`]'s output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AccessControl {
    /// The `rules` list items.
    pub rules: Vec<String>,
    /// The `policies` list items.
    pub policies: Vec<String>,
}

fn quoted(names: &[&str]) -> String {
    names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RunId;

    /// Every concrete topic of a run belongs to exactly one family of the registry.
    #[test]
    fn every_topic_has_one_entry() {
        let run = RunId::new("r").unwrap();
        let matches = |pattern: &str, key: &str| {
            let (p, k): (Vec<&str>, Vec<&str>) = (pattern.split('/').collect(), key.split('/').collect());
            p.len() == k.len() && p.iter().zip(&k).all(|(p, k)| *p == "*" || p == k)
        };
        let keys: Vec<String> = crate::topics::examples().iter().map(|t| t.key(&run)).collect();
        for key in &keys {
            let families: Vec<&str> =
                TOPICS.iter().filter(|e| matches(&e.wildcard(), key)).map(|e| e.key).collect();
            assert_eq!(families.len(), 1, "{key}: {families:?}");
        }
        for entry in TOPICS {
            assert!(keys.iter().any(|k| matches(&entry.wildcard(), k)), "{} names no topic", entry.key);
        }
    }

    #[test]
    fn writers_are_protected_and_own_topics_name_the_role() {
        let acl = access_control();
        let sample = acl.rules.iter().find(|r| r.contains(r#"id: "learner-queries""#)).unwrap();
        assert!(sample.contains("rl/*/replay/sample"), "{sample}");
        let own = acl.rules.iter().find(|r| r.contains(r#"id: "own-param""#)).unwrap();
        assert!(own.contains("rl/*/stats/param/*") && own.contains("rl/*/liveliness/param/*"), "{own}");
        // The policy of a rule binds every certificate role but the one it protects.
        let policy = acl.policies.iter().find(|p| p.contains(r#"["replay-serves"]"#)).unwrap();
        assert!(!policy.contains(r#""replay""#) && policy.contains(r#""monitor""#), "{policy}");
        assert_eq!(acl.rules.len(), acl.policies.len());
    }
}
