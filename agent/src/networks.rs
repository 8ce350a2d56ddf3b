//! All networks of one level, each in its own [`VarMap`]: policy, Q1 (and Q2), V and target V-bar.
//! Shared by the [`Learner`](crate::Learner), which trains them, and the [`Actor`](crate::Actor),
//! which loads them from snapshots.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;

use crate::config::AgentConfig;
use crate::critic::{QNet, ValueNet};
use crate::error::Result;
use crate::policy::LatentPolicy;
use crate::vars::{SeededInit, check, export, import, set_checked};

/// A model and the variables it was built from; names in `vars` are relative to the network.
pub(crate) struct Net<M> {
    /// Snapshot prefix of the network's tensors.
    pub role: &'static str,
    pub vars: VarMap,
    pub model: M,
}

impl<M: std::fmt::Debug> std::fmt::Debug for Net<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Net").field("role", &self.role).field("model", &self.model).finish_non_exhaustive()
    }
}

impl<M> Net<M> {
    fn build(
        role: &'static str,
        init: &SeededInit,
        dtype: DType,
        make: impl FnOnce(candle_nn::VarBuilder<'static>) -> candle_core::Result<M>,
    ) -> Result<Self> {
        let vars = VarMap::new();
        let model = make(init.builder(&vars, dtype, &Device::Cpu))?;
        Ok(Self { role, vars, model })
    }

    pub fn export(&self, out: &mut Vec<(String, Tensor)>) -> Result<()> {
        export(self.role, &self.vars, out)
    }

    pub fn import(&self, tensors: &HashMap<String, Tensor>) -> Result<()> {
        import(self.role, &self.vars, tensors)
    }
}

/// Builds a policy alone (a frozen stack level), initialised from `init`.
pub(crate) fn policy_net(cfg: &AgentConfig, init: &SeededInit, dtype: DType) -> Result<Net<LatentPolicy>> {
    Net::build("policy", init, dtype, |vb| LatentPolicy::new(cfg, vb))
}

/// The networks of one level.
#[derive(Debug)]
pub(crate) struct Networks {
    pub policy: Net<LatentPolicy>,
    /// Q1, then Q2 with twin Q.
    pub qs: Vec<Net<QNet>>,
    pub v: Net<ValueNet>,
    pub v_target: Net<ValueNet>,
}

impl Networks {
    /// Builds every network, in the order policy, Q1, (Q2), V, V-bar, from one seeded initialiser;
    /// V-bar is initialised independently of V (the paper's quirk; see `Learner::new`).
    pub fn new(cfg: &AgentConfig, seed: u64, dtype: DType) -> Result<Self> {
        let init = SeededInit::new(seed);
        let policy = policy_net(cfg, &init, dtype)?;
        let roles: &[&'static str] = if cfg.twin_q { &["q1", "q2"] } else { &["q1"] };
        let qs = roles
            .iter()
            .map(|role| Net::build(role, &init, dtype, |vb| QNet::new(cfg, vb)))
            .collect::<Result<_>>()?;
        let v = Net::build("v", &init, dtype, |vb| ValueNet::new(cfg, vb))?;
        let v_target = Net::build("v_target", &init, dtype, |vb| ValueNet::new(cfg, vb))?;
        Ok(Self { policy, qs, v, v_target })
    }

    /// Every network's role and variables, in the order policy, Q1, (Q2), V, V-bar.
    fn var_maps(&self) -> Vec<(&'static str, &VarMap)> {
        let mut maps = vec![(self.policy.role, &self.policy.vars)];
        maps.extend(self.qs.iter().map(|q| (q.role, &q.vars)));
        maps.push((self.v.role, &self.v.vars));
        maps.push((self.v_target.role, &self.v_target.vars));
        maps
    }

    /// Every network's tensors under `{role}.{name}`.
    pub fn export(&self, out: &mut Vec<(String, Tensor)>) -> Result<()> {
        self.var_maps().into_iter().try_for_each(|(role, vars)| export(role, vars, out))
    }

    /// Sets every network from `tensors`; all names must be present with their shapes and finite
    /// values, else no network changes (a bad snapshot leaves an actor acting as before).
    pub fn import(&self, tensors: &HashMap<String, Tensor>) -> Result<()> {
        let maps = self.var_maps();
        maps.iter().try_for_each(|(role, vars)| check(role, vars, tensors))?;
        maps.iter().try_for_each(|(role, vars)| set_checked(role, vars, tensors))
    }
}
