//! Where every parameter of one SAC-LSP level lives in the fused learner's flat `f32` arena, under
//! the same names as the candle networks (`{role}.{vb.pp path}`, see `params.rs`).
//!
//! Arrays are placed in an order chosen for speed, not by name: the first-layer weights of V, of
//! the policy embedding and the observation part of Q are adjacent, so together they form one
//! `[H_v + H_e + H_q, obs_dim]` row-major matrix and the three products with s (and their three
//! weight gradients) run as one wide GEMM each.

use std::collections::HashMap;

use candle_core::{Device, Tensor};

use crate::config::AgentConfig;
use crate::coupling::Parity;
use crate::error::{Error, Result};

/// The networks of a level, with their snapshot prefixes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Role {
    /// The latent-space policy (embedding and coupling layers).
    Policy,
    /// Q1.
    Q,
    /// Q2, with twin Q.
    Q2,
    /// V.
    V,
    /// The target V-bar.
    VTarget,
    /// log alpha, when the temperature is learned (in checkpoints, not in snapshots).
    Temperature,
}

impl Role {
    /// The trained parameter sets, in the order the candle learner steps their Adams.
    pub(crate) const TRAINED: [Role; 5] = [Role::Q, Role::Q2, Role::V, Role::Policy, Role::Temperature];

    /// The networks of a weights snapshot.
    pub(crate) const NETWORKS: [Role; 5] = [Role::Policy, Role::Q, Role::Q2, Role::V, Role::VTarget];

    /// Everything of a checkpoint: the networks and the learned temperature.
    pub(crate) const ALL: [Role; 6] =
        [Role::Policy, Role::Q, Role::Q2, Role::V, Role::VTarget, Role::Temperature];

    /// Position in [`Role::TRAINED`] (and in the learner's Adam step counts); `None` for V-bar.
    pub(crate) fn adam_index(self) -> Option<usize> {
        Self::TRAINED.iter().position(|r| *r == self)
    }

    /// Prefix of the network's tensors in snapshots and of its Adam in checkpoints.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Policy => "policy",
            Self::Q => "q1",
            Self::Q2 => "q2",
            Self::V => "v",
            Self::VTarget => "v_target",
            Self::Temperature => "temperature",
        }
    }
}

/// One named parameter tensor in the arena.
#[derive(Clone, Debug)]
pub(crate) struct ParamArray {
    /// Network it belongs to.
    pub role: Role,
    /// Name relative to the network, e.g. `layer0.weight_action`.
    pub name: String,
    /// `[out, in]` for weights, `[out]` for biases.
    pub shape: Vec<usize>,
    /// First element in the arena.
    pub offset: usize,
    /// Number of elements.
    pub len: usize,
}

/// A dense layer y = x W^T + b: arena offsets of W (`[out, fan_in]`) and b (`[out]`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct DenseAt {
    pub weight: usize,
    pub bias: usize,
    pub fan_in: usize,
    pub out: usize,
}

/// The layers of one MLP, first to last.
#[derive(Clone, Debug)]
pub(crate) struct MlpAt {
    pub layers: Vec<DenseAt>,
}

impl MlpAt {
    /// Output width of every layer.
    pub(crate) fn widths(&self) -> Vec<usize> {
        self.layers.iter().map(|l| l.out).collect()
    }
}

/// One coupling layer: which columns of x it keeps and moves, and its s and t nets, whose input
/// is [kept half, c].
#[derive(Clone, Debug)]
pub(crate) struct CouplingAt {
    pub kept_from: usize,
    pub kept: usize,
    pub moved_from: usize,
    pub moved: usize,
    pub scale: MlpAt,
    pub translation: MlpAt,
}

/// The first-layer weights that multiply s, stacked: rows `[0, v)` are V's, `[v, v + e)` the
/// embedding's, then each Q's observation weights (Q1, then Q2 with twin Q; see [`QAt::obs`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObsBlock {
    pub weight: usize,
    pub rows: usize,
    pub v: usize,
    pub embedding: usize,
}

/// One Q network: its role, layers (layer 0's `weight` is its observation matrix, inside the
/// [`ObsBlock`] at rows `obs ..`), and its `layer0.weight_action`, `[H_q, act_dim]`.
#[derive(Clone, Debug)]
pub(crate) struct QAt {
    pub role: Role,
    pub mlp: MlpAt,
    pub obs: usize,
    pub action_weight: usize,
}

/// V-bar's array at `target` is Polyak-averaged towards V's array at `online` (same name).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PolyakPair {
    pub online: usize,
    pub target: usize,
    pub len: usize,
}

/// The whole arena.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    pub arrays: Vec<ParamArray>,
    pub len: usize,
    pub obs: ObsBlock,
    pub v: MlpAt,
    pub v_target: MlpAt,
    /// Q1, then Q2 with twin Q.
    pub qs: Vec<QAt>,
    pub embedding: MlpAt,
    /// The coupling layers that move something, in order; a 1-d action's odd layer is the
    /// identity and has no parameters (as in `coupling.rs`), so it is left out.
    pub couplings: Vec<CouplingAt>,
    /// log alpha's offset, when the temperature is learned.
    pub log_alpha: Option<usize>,
    /// V-bar's arrays with their V counterparts; every target lies after its online array.
    pub polyak: Vec<PolyakPair>,
    /// The roles that own arrays, so [`Layout::has`] needs no scan on the update's path.
    roles: Vec<Role>,
}

struct Builder {
    arrays: Vec<ParamArray>,
    len: usize,
}

impl Builder {
    fn push(&mut self, role: Role, name: String, shape: &[usize]) -> usize {
        let offset = self.len;
        let len = shape.iter().product();
        self.arrays.push(ParamArray { role, name, shape: shape.to_vec(), offset, len });
        self.len += len;
        offset
    }

    /// Layer `k` of an MLP under `prefix`, whose weight may already have been placed.
    fn dense(
        &mut self,
        role: Role,
        prefix: &str,
        k: usize,
        fan_in: usize,
        out: usize,
        weight: Option<usize>,
    ) -> DenseAt {
        let weight =
            weight.unwrap_or_else(|| self.push(role, format!("{prefix}layer{k}.weight"), &[out, fan_in]));
        let bias = self.push(role, format!("{prefix}layer{k}.bias"), &[out]);
        DenseAt { weight, bias, fan_in, out }
    }

    /// An MLP with widths `layers` on `fan_in` inputs; layer 0's weight may already be placed.
    fn mlp(
        &mut self,
        role: Role,
        prefix: &str,
        fan_in: usize,
        layers: &[usize],
        first_weight: Option<usize>,
    ) -> MlpAt {
        let mut prev = fan_in;
        let layers = layers
            .iter()
            .enumerate()
            .map(|(k, &out)| {
                let layer = self.dense(role, prefix, k, prev, out, if k == 0 { first_weight } else { None });
                prev = out;
                layer
            })
            .collect();
        MlpAt { layers }
    }
}

impl Layout {
    /// The arena of `cfg`'s networks.
    pub(crate) fn new(cfg: &AgentConfig) -> Self {
        let (obs, act) = (cfg.obs_dim, cfg.act_dim);
        let critic = cfg.critic_layers();
        let (h_v, h_e, h_q) = (critic[0], cfg.embedding_layers[0], critic[0]);
        let q_roles: &[Role] = if cfg.twin_q { &[Role::Q, Role::Q2] } else { &[Role::Q] };
        let mut b = Builder { arrays: Vec::new(), len: 0 };
        let v_w = b.push(Role::V, "layer0.weight".into(), &[h_v, obs]);
        let e_w = b.push(Role::Policy, "embedding.layer0.weight".into(), &[h_e, obs]);
        let q_ws: Vec<usize> =
            q_roles.iter().map(|r| b.push(*r, "layer0.weight_observation".into(), &[h_q, obs])).collect();
        let obs_block = ObsBlock { weight: v_w, rows: h_v + h_e + q_roles.len() * h_q, v: 0, embedding: h_v };
        let v = b.mlp(Role::V, "", obs, &critic, Some(v_w));
        let qs = q_roles
            .iter()
            .zip(q_ws)
            .enumerate()
            .map(|(k, (role, q_w))| {
                let action_weight = b.push(*role, "layer0.weight_action".into(), &[h_q, act]);
                let mlp = b.mlp(*role, "", obs, &critic, Some(q_w));
                QAt { role: *role, mlp, obs: h_v + h_e + k * h_q, action_weight }
            })
            .collect();
        let embedding = b.mlp(Role::Policy, "embedding.", obs, &cfg.embedding_layers, Some(e_w));
        let context = *cfg.embedding_layers.last().unwrap_or(&0);
        let split = act / 2;
        let couplings = (0..cfg.coupling_layers)
            .filter_map(|i| {
                let (kept_from, kept, moved_from, moved) = match Parity::of_layer(i) {
                    Parity::Odd => (split, act - split, 0, split),
                    Parity::Even => (0, split, split, act - split),
                };
                if moved == 0 {
                    return None;
                }
                let mut widths = cfg.coupling_hidden.clone();
                widths.push(moved);
                let scale =
                    b.mlp(Role::Policy, &format!("coupling{i}.scale."), kept + context, &widths, None);
                let translation =
                    b.mlp(Role::Policy, &format!("coupling{i}.translation."), kept + context, &widths, None);
                Some(CouplingAt { kept_from, kept, moved_from, moved, scale, translation })
            })
            .collect();
        let v_target = b.mlp(Role::VTarget, "", obs, &critic, None);
        let log_alpha = cfg.learn_temperature.then(|| b.push(Role::Temperature, "log_alpha".into(), &[1]));
        let polyak = b
            .arrays
            .iter()
            .filter(|t| t.role == Role::VTarget)
            .filter_map(|t| {
                let o = b.arrays.iter().find(|o| o.role == Role::V && o.name == t.name)?;
                Some(PolyakPair { online: o.offset, target: t.offset, len: t.len })
            })
            .collect();
        let roles = Role::ALL.into_iter().filter(|r| b.arrays.iter().any(|a| a.role == *r)).collect();
        Self {
            arrays: b.arrays,
            len: b.len,
            obs: obs_block,
            v,
            v_target,
            qs,
            embedding,
            couplings,
            log_alpha,
            polyak,
            roles,
        }
    }

    /// Whether any array belongs to `role` (Q2 and the temperature are optional).
    pub(crate) fn has(&self, role: Role) -> bool {
        self.roles.contains(&role)
    }

    /// Copies `tensors[{prefix}.{name}]` into `dst` for every array of the roles in `roles`; all
    /// must be present with the layout's shape. `prefix(role)` gives the key prefix.
    pub(crate) fn import(
        &self,
        roles: &[Role],
        prefix: impl Fn(Role) -> String,
        tensors: &HashMap<String, Tensor>,
        dst: &mut [f32],
    ) -> Result<()> {
        for a in self.arrays.iter().filter(|a| roles.contains(&a.role)) {
            let key = format!("{}.{}", prefix(a.role), a.name);
            let t = tensors.get(&key).ok_or_else(|| Error::BadSnapshot(format!("missing tensor {key}")))?;
            if t.dims() != a.shape.as_slice() {
                return Err(Error::BadSnapshot(format!(
                    "{key}: shape {:?} in snapshot, {:?} in network",
                    t.dims(),
                    a.shape
                )));
            }
            let values = t.to_dtype(candle_core::DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
            dst[a.offset..a.offset + a.len].copy_from_slice(&values);
        }
        Ok(())
    }

    /// `{role}.{name}` and the shape of every array of the roles in `roles`, as snapshots name them.
    pub(crate) fn names_and_shapes<'a>(
        &'a self,
        roles: &'a [Role],
    ) -> impl Iterator<Item = (String, Vec<usize>)> + 'a {
        self.arrays
            .iter()
            .filter(|a| roles.contains(&a.role))
            .map(|a| (format!("{}.{}", a.role.name(), a.name), a.shape.clone()))
    }

    /// Appends every array of the roles in `roles` as `{prefix(role)}.{name}` tensors.
    pub(crate) fn export(
        &self,
        roles: &[Role],
        prefix: impl Fn(Role) -> String,
        src: &[f32],
        out: &mut Vec<(String, Tensor)>,
    ) -> Result<()> {
        for a in self.arrays.iter().filter(|a| roles.contains(&a.role)) {
            let values = &src[a.offset..a.offset + a.len];
            let t = Tensor::from_slice(values, a.shape.as_slice(), &Device::Cpu)?;
            out.push((format!("{}.{}", prefix(a.role), a.name), t));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Learner;

    #[test]
    fn arena_names_and_shapes_are_the_candle_learners() {
        let cfg = AgentConfig {
            critic_hidden: vec![6, 5],
            embedding_layers: vec![5, 3],
            coupling_hidden: vec![3],
            coupling_layers: 3,
            ..AgentConfig::for_task(3, 5)
        };
        let layout = Layout::new(&cfg);
        let snapshot = Learner::new(cfg.clone(), 1).unwrap().snapshot().unwrap().tensors().unwrap();
        let mut ours: Vec<(String, Vec<usize>)> = layout.names_and_shapes(&Role::ALL).collect();
        let mut theirs: Vec<(String, Vec<usize>)> =
            snapshot.iter().map(|(n, t)| (n.clone(), t.dims().to_vec())).collect();
        ours.sort();
        theirs.sort();
        assert_eq!(ours, theirs);
        // With every option and a 1-d action: Q2 beside Q1 in the stacked block, log alpha as in
        // the candle checkpoint, no arrays for the identity coupling layer.
        for options in [
            AgentConfig { twin_q: true, learn_temperature: true, ..cfg.clone() },
            AgentConfig { twin_q: true, learn_temperature: true, act_dim: 1, ..cfg.clone() },
        ] {
            let layout = Layout::new(&options);
            let checkpoint = Learner::new(options.clone(), 1).unwrap().checkpoint().unwrap();
            let tensors = crate::params::decode(&checkpoint.safetensors).unwrap();
            let mut theirs: Vec<(String, Vec<usize>)> = tensors
                .iter()
                .filter(|(n, _)| !n.starts_with("adam.") && !n.starts_with("learner."))
                .map(|(n, t)| (n.clone(), t.dims().to_vec()))
                .collect();
            let mut ours: Vec<(String, Vec<usize>)> = layout.names_and_shapes(&Role::ALL).collect();
            ours.sort();
            theirs.sort();
            assert_eq!(ours, theirs, "act_dim {}", options.act_dim);
            assert_eq!((layout.obs.rows, layout.qs[1].obs), (6 + 5 + 2 * 6, 17));
            assert!(layout.has(Role::Q2) && layout.log_alpha.is_some());
        }
        assert_eq!(layout.len, layout.arrays.iter().map(|a| a.len).sum::<usize>());
        // The stacked first layer: V's, the embedding's and Q's observation weights, adjacent.
        assert_eq!((layout.obs.rows, layout.obs.embedding, layout.qs[0].obs), (6 + 5 + 6, 6, 11));
        assert_eq!(layout.embedding.layers[0].weight, layout.obs.weight + 6 * 3);
        // Odd (first) layer keeps the upper half, 5 = 2 moved + 3 kept.
        let c = &layout.couplings[0];
        assert_eq!((c.kept_from, c.kept, c.moved_from, c.moved), (2, 3, 0, 2));
        let c = &layout.couplings[1];
        assert_eq!((c.kept_from, c.kept, c.moved_from, c.moved), (0, 2, 2, 3));
    }
}
