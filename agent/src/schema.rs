//! The tensor names and shapes of a level's weights (named as in `params.rs`), both ways: the
//! schema of a configuration's networks, and the configuration a file of weights was made with.

use std::collections::BTreeMap;

use crate::config::{AgentConfig, CategoricalConfig, CategoricalVariant, Critic};
use crate::error::{Error, Result};
use crate::fused::layout::{Layout, Role};

/// Tensor names and their shapes.
pub type Schema = BTreeMap<String, Vec<usize>>;

/// The tensor names and shapes of a [`ParamSnapshot`](crate::ParamSnapshot) of `cfg`'s networks:
/// what both learners export and every actor imports. Computed from the layout alone (no network
/// is built), so a role that only relays weights can check them against the run's networks.
pub fn snapshot_schema(cfg: &AgentConfig) -> Schema {
    Layout::new(cfg).names_and_shapes(&Role::NETWORKS).collect()
}

/// The networks (dimensions, widths, coupling layers, twin Q) whose snapshot has the tensors in
/// `schema`; other tensors, such as a checkpoint's Adam moments, are ignored. What shapes cannot
/// tell keeps `base`'s value (a squashed action and a ReLU embedding output for a bottom level,
/// the prior and the update's settings, which acting does not use). The result is checked: its
/// own schema must be in `schema`, shape for shape.
pub fn networks_from_schema(schema: &Schema, base: &AgentConfig) -> Result<AgentConfig> {
    let bad = |msg: String| Error::BadSnapshot(msg);
    let shape = |name: &str| schema.get(name).ok_or_else(|| bad(format!("no tensor {name}")));
    let outputs = |prefix: &str, first: &str| -> Vec<usize> {
        let weight = |k: usize| {
            if k == 0 { format!("{prefix}layer0.{first}") } else { format!("{prefix}layer{k}.weight") }
        };
        (0..).map_while(|k| schema.get(&weight(k)).and_then(|s| s.first().copied())).collect()
    };
    let observation = shape("q1.layer0.weight_observation")?;
    let action = shape("q1.layer0.weight_action")?;
    let (obs_dim, act_dim) = (observation.get(1).copied().unwrap_or(0), action.get(1).copied().unwrap_or(0));
    let mut critic_hidden = outputs("q1.", "weight_observation");
    // The head: one output (scalar), the atoms' logits, or a width-1 layer then the atoms'
    // logits (the dissertation's categorical critic). The support's bounds keep `base`'s values.
    let (critic, categorical) = match critic_hidden.pop() {
        Some(1) => (Critic::Scalar, base.categorical.clone()),
        Some(atoms) if critic_hidden.last() == Some(&1) => {
            critic_hidden.pop();
            let variant = CategoricalVariant::Dissertation;
            (Critic::Categorical, CategoricalConfig { variant, atoms, ..base.categorical.clone() })
        }
        Some(atoms) => {
            let variant = CategoricalVariant::SoftC51;
            (Critic::Categorical, CategoricalConfig { variant, atoms, ..base.categorical.clone() })
        }
        None => return Err(bad("q1 has no layers".into())),
    };
    let embedding_layers = outputs("policy.embedding.", "weight");
    let couplings: Vec<usize> = schema
        .keys()
        .filter_map(|name| name.strip_prefix("policy.coupling")?.split('.').next()?.parse().ok())
        .collect();
    let coupling_layers = couplings.iter().max().map_or(0, |last| last + 1);
    let first = couplings.iter().min().copied().unwrap_or(0);
    let mut coupling_hidden = outputs(&format!("policy.coupling{first}.scale."), "weight");
    coupling_hidden.pop();
    let cfg = AgentConfig {
        obs_dim,
        act_dim,
        critic_hidden,
        embedding_layers,
        coupling_layers,
        coupling_hidden,
        twin_q: schema.contains_key("q2.layer0.weight_action"),
        critic,
        categorical,
        ..base.clone()
    };
    cfg.validate().map_err(|e| bad(format!("the tensors describe no valid networks: {e}")))?;
    if let Some((name, expected)) = snapshot_schema(&cfg).into_iter().find(|(n, s)| schema.get(n) != Some(s))
    {
        let found = schema.get(&name).map_or("missing".to_string(), |s| format!("{s:?}"));
        return Err(bad(format!("{name}: {found}, but networks {obs_dim}->{act_dim} expect {expected:?}")));
    }
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schema_is_what_the_learners_snapshot() {
        let small = AgentConfig {
            critic_hidden: vec![6, 5],
            embedding_layers: vec![5, 3],
            coupling_hidden: vec![3],
            ..AgentConfig::for_task(4, 3)
        };
        for cfg in [
            small.clone(),
            AgentConfig { twin_q: true, learn_temperature: true, ..small.clone() },
            AgentConfig { twin_q: true, act_dim: 1, ..small.clone() },
            AgentConfig { critic: Critic::Categorical, ..small.clone() },
            AgentConfig {
                critic: Critic::Categorical,
                categorical: CategoricalConfig {
                    variant: CategoricalVariant::Dissertation,
                    ..Default::default()
                },
                ..small
            },
        ] {
            let learner = crate::Learner::new(cfg.clone(), 3).unwrap();
            let theirs: BTreeMap<String, Vec<usize>> = learner
                .snapshot()
                .unwrap()
                .tensors()
                .unwrap()
                .into_iter()
                .map(|(name, t)| (name, t.dims().to_vec()))
                .collect();
            assert_eq!(snapshot_schema(&cfg), theirs, "twin_q {} act_dim {}", cfg.twin_q, cfg.act_dim);
        }
        // Widths change the schema, so a snapshot of other networks cannot pass for this one.
        let wider = AgentConfig { critic_hidden: vec![7, 5], ..AgentConfig::for_task(4, 3) };
        assert_ne!(snapshot_schema(&wider), snapshot_schema(&AgentConfig::for_task(4, 3)));
    }

    #[test]
    fn the_networks_are_read_back_from_their_schema() {
        let small = AgentConfig {
            critic_hidden: vec![6, 5],
            embedding_layers: vec![5, 3],
            coupling_hidden: vec![3, 2],
            coupling_layers: 3,
            ..AgentConfig::for_task(4, 3)
        };
        let base = AgentConfig::default();
        for cfg in [
            small.clone(),
            AgentConfig { twin_q: true, ..small.clone() },
            AgentConfig { act_dim: 1, ..small.clone() },
            AgentConfig { coupling_hidden: vec![], ..small.clone() },
            AgentConfig::for_task(105, 8),
            AgentConfig { critic: Critic::Categorical, ..small.clone() },
            AgentConfig {
                critic: Critic::Categorical,
                categorical: CategoricalConfig {
                    variant: CategoricalVariant::Dissertation,
                    atoms: 11,
                    ..Default::default()
                },
                ..small.clone()
            },
        ] {
            let mut schema = snapshot_schema(&cfg);
            // A checkpoint's other tensors are ignored.
            schema.insert("adam.q1.m.layer0.bias".into(), vec![6]);
            schema.insert("learner.step".into(), vec![1]);
            let back = networks_from_schema(&schema, &base).unwrap();
            assert_eq!(snapshot_schema(&back), snapshot_schema(&cfg));
            if cfg.act_dim > 1 {
                assert_eq!(back, cfg);
            } else {
                // A 1-d action's identity coupling layers have no tensors: a trailing one is not
                // counted, which acts the same.
                assert_eq!((back.coupling_layers, back.critic_hidden.as_slice()), (2, &[6, 5][..]));
            }
        }
        // A wrong shape or a missing tensor is named.
        let mut schema = snapshot_schema(&small);
        schema.insert("v.layer1.weight".into(), vec![9, 9]);
        let err = networks_from_schema(&schema, &base).unwrap_err().to_string();
        assert!(err.contains("v.layer1.weight: [9, 9]"), "{err}");
        let mut schema = snapshot_schema(&small);
        schema.remove("policy.embedding.layer1.bias");
        assert!(
            networks_from_schema(&schema, &base)
                .unwrap_err()
                .to_string()
                .contains("policy.embedding.layer1.bias")
        );
        assert!(
            networks_from_schema(&Schema::new(), &base).unwrap_err().to_string().contains("no tensor q1.")
        );
    }
}
