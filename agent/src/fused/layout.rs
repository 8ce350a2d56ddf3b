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
    /// V.
    V,
    /// The target V-bar.
    VTarget,
}

impl Role {
    /// The trained networks, in the order the candle learner steps their Adams.
    pub(crate) const TRAINED: [Role; 3] = [Role::Q, Role::V, Role::Policy];

    /// Position in [`Role::TRAINED`] (and in the learner's Adam step counts); `None` for V-bar.
    pub(crate) fn adam_index(self) -> Option<usize> {
        Self::TRAINED.iter().position(|r| *r == self)
    }

    /// Prefix of the network's tensors in snapshots and of its Adam in checkpoints.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Policy => "policy",
            Self::Q => "q1",
            Self::V => "v",
            Self::VTarget => "v_target",
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
/// embedding's, `[v + e, rows)` Q's observation weights.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObsBlock {
    pub weight: usize,
    pub rows: usize,
    pub v: usize,
    pub embedding: usize,
    pub q: usize,
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
    /// Q's layers; layer 0's `weight` is its observation matrix (inside `obs`).
    pub q: MlpAt,
    /// Q's `layer0.weight_action`, `[H_q, act_dim]`.
    pub q_action_weight: usize,
    pub embedding: MlpAt,
    pub couplings: Vec<CouplingAt>,
    /// V-bar's arrays with their V counterparts; every target lies after its online array.
    pub polyak: Vec<PolyakPair>,
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
    /// The arena of `cfg`'s networks (single Q, as [`FusedLearner::supports`](super::FusedLearner::supports)
    /// requires).
    pub(crate) fn new(cfg: &AgentConfig) -> Self {
        let (obs, act) = (cfg.obs_dim, cfg.act_dim);
        let mut critic = cfg.critic_hidden.clone();
        critic.push(1);
        let (h_v, h_e, h_q) = (critic[0], cfg.embedding_layers[0], critic[0]);
        let mut b = Builder { arrays: Vec::new(), len: 0 };
        let v_w = b.push(Role::V, "layer0.weight".into(), &[h_v, obs]);
        let e_w = b.push(Role::Policy, "embedding.layer0.weight".into(), &[h_e, obs]);
        let q_w = b.push(Role::Q, "layer0.weight_observation".into(), &[h_q, obs]);
        let obs_block = ObsBlock { weight: v_w, rows: h_v + h_e + h_q, v: 0, embedding: h_v, q: h_v + h_e };
        let v = b.mlp(Role::V, "", obs, &critic, Some(v_w));
        let q_action_weight = b.push(Role::Q, "layer0.weight_action".into(), &[h_q, act]);
        let q = b.mlp(Role::Q, "", obs, &critic, Some(q_w));
        let embedding = b.mlp(Role::Policy, "embedding.", obs, &cfg.embedding_layers, Some(e_w));
        let context = *cfg.embedding_layers.last().unwrap_or(&0);
        let split = act / 2;
        let couplings = (0..cfg.coupling_layers)
            .map(|i| {
                let (kept_from, kept, moved_from, moved) = match Parity::of_layer(i) {
                    Parity::Odd => (split, act - split, 0, split),
                    Parity::Even => (0, split, split, act - split),
                };
                let mut widths = cfg.coupling_hidden.clone();
                widths.push(moved);
                let scale =
                    b.mlp(Role::Policy, &format!("coupling{i}.scale."), kept + context, &widths, None);
                let translation =
                    b.mlp(Role::Policy, &format!("coupling{i}.translation."), kept + context, &widths, None);
                CouplingAt { kept_from, kept, moved_from, moved, scale, translation }
            })
            .collect();
        let v_target = b.mlp(Role::VTarget, "", obs, &critic, None);
        let polyak = b
            .arrays
            .iter()
            .filter(|t| t.role == Role::VTarget)
            .filter_map(|t| {
                let o = b.arrays.iter().find(|o| o.role == Role::V && o.name == t.name)?;
                Some(PolyakPair { online: o.offset, target: t.offset, len: t.len })
            })
            .collect();
        Self {
            arrays: b.arrays,
            len: b.len,
            obs: obs_block,
            v,
            v_target,
            q,
            q_action_weight,
            embedding,
            couplings,
            polyak,
        }
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
        let snapshot = Learner::new(cfg, 1).unwrap().snapshot().unwrap().tensors().unwrap();
        let mut ours: Vec<(String, Vec<usize>)> = layout
            .arrays
            .iter()
            .map(|a| (format!("{}.{}", a.role.name(), a.name), a.shape.clone()))
            .collect();
        let mut theirs: Vec<(String, Vec<usize>)> =
            snapshot.iter().map(|(n, t)| (n.clone(), t.dims().to_vec())).collect();
        ours.sort();
        theirs.sort();
        assert_eq!(ours, theirs);
        assert_eq!(layout.len, layout.arrays.iter().map(|a| a.len).sum::<usize>());
        // The stacked first layer: V's, the embedding's and Q's observation weights, adjacent.
        assert_eq!((layout.obs.rows, layout.obs.embedding, layout.obs.q), (6 + 5 + 6, 6, 11));
        assert_eq!(layout.embedding.layers[0].weight, layout.obs.weight + 6 * 3);
        // Odd (first) layer keeps the upper half, 5 = 2 moved + 3 kept.
        let c = &layout.couplings[0];
        assert_eq!((c.kept_from, c.kept, c.moved_from, c.moved), (2, 3, 0, 2));
        let c = &layout.couplings[1];
        assert_eq!((c.kept_from, c.kept, c.moved_from, c.moved), (0, 2, 2, 3));
    }
}
