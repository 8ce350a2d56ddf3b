//! Variables of one network: a [`VarMap`] filled through a seeded initialiser.
//!
//! candle's own `Init` draws from a thread-local RNG, so `Learner::new(cfg, seed)` could not be
//! reproducible with it. [`SeededInit`] is a `VarBuilder` backend that creates each variable in a
//! `VarMap` from one seeded RNG, in construction order. Names are the `vb.pp(..)` paths relative to
//! the network, so an online net and its target have identical names in their own maps.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use candle_core::{DType, Device, Shape, Tensor, Var};
use candle_nn::{Init, VarBuilder, VarMap, var_builder::SimpleBackend};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

use crate::error::{Error, Result};

/// A seeded source of initial values, shared by all networks built for one agent.
#[derive(Clone, Debug)]
pub(crate) struct SeededInit {
    rng: Arc<Mutex<StdRng>>,
}

impl SeededInit {
    pub(crate) fn new(seed: u64) -> Self {
        Self { rng: Arc::new(Mutex::new(StdRng::seed_from_u64(seed))) }
    }

    /// A builder whose new variables land in `map`, initialised from this RNG.
    pub(crate) fn builder(&self, map: &VarMap, dtype: DType, device: &Device) -> VarBuilder<'static> {
        let backend = Backend { map: map.clone(), rng: self.rng.clone() };
        VarBuilder::from_backend(Box::new(backend), dtype, device.clone())
    }
}

struct Backend {
    map: VarMap,
    rng: Arc<Mutex<StdRng>>,
}

impl Backend {
    fn draw(&self, n: usize, init: Init) -> candle_core::Result<Vec<f64>> {
        let mut rng = self.rng.lock().map_err(|_| candle_core::Error::Msg("init rng poisoned".into()))?;
        Ok(match init {
            Init::Const(c) => vec![c; n],
            Init::Uniform { lo, up } => (0..n).map(|_| rng.random_range(lo..up)).collect(),
            Init::Randn { mean, stdev } => {
                (0..n).map(|_| mean + stdev * rng.sample::<f64, _>(StandardNormal)).collect()
            }
            Init::Kaiming { .. } => candle_core::bail!("kaiming init is not used by this crate"),
        })
    }
}

impl SimpleBackend for Backend {
    fn get(&self, s: Shape, name: &str, h: Init, dtype: DType, dev: &Device) -> candle_core::Result<Tensor> {
        let mut data =
            self.map.data().lock().map_err(|_| candle_core::Error::Msg("var map poisoned".into()))?;
        if let Some(var) = data.get(name) {
            let t = var.as_tensor();
            if t.shape() != &s {
                candle_core::bail!("{name}: shape {:?} requested, {:?} exists", s, t.shape());
            }
            return Ok(t.clone());
        }
        let values = self.draw(s.elem_count(), h)?;
        let var = Var::from_tensor(&Tensor::from_vec(values, s, dev)?.to_dtype(dtype)?)?;
        let t = var.as_tensor().clone();
        data.insert(name.to_string(), var);
        Ok(t)
    }

    fn get_unchecked(&self, name: &str, _: DType, _: &Device) -> candle_core::Result<Tensor> {
        candle_core::bail!("{name}: a seeded var map needs a shape")
    }

    fn contains_tensor(&self, name: &str) -> bool {
        self.map.data().lock().map(|d| d.contains_key(name)).unwrap_or(false)
    }
}

/// The variables of `map`, sorted by name.
pub(crate) fn sorted_vars(map: &VarMap) -> Result<Vec<(String, Var)>> {
    let data = map.data().lock().map_err(|_| Error::BadInput("var map poisoned".into()))?;
    let mut vars: Vec<(String, Var)> = data.iter().map(|(n, v)| (n.clone(), v.clone())).collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(vars)
}

/// Appends `map`'s variables to `out` as `{role}.{name}`.
pub(crate) fn export(role: &str, map: &VarMap, out: &mut Vec<(String, Tensor)>) -> Result<()> {
    for (name, var) in sorted_vars(map)? {
        out.push((format!("{role}.{name}"), var.as_tensor().clone()));
    }
    Ok(())
}

/// Checks that `tensors` holds every variable of `map` as `{role}.{name}` with its shape and only
/// finite values, changing nothing: the first half of an import that either takes a whole snapshot
/// or leaves the weights as they were.
pub(crate) fn check(role: &str, map: &VarMap, tensors: &HashMap<String, Tensor>) -> Result<()> {
    for (name, var) in sorted_vars(map)? {
        let key = format!("{role}.{name}");
        let t = tensors.get(&key).ok_or_else(|| Error::BadSnapshot(format!("missing tensor {key}")))?;
        if t.shape() != var.shape() {
            return Err(Error::BadSnapshot(format!(
                "{key}: shape {:?} in snapshot, {:?} in network",
                t.shape(),
                var.shape()
            )));
        }
        let values = t.to_dtype(candle_core::DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
        if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
            return Err(Error::BadSnapshot(format!("{key}: non-finite value {bad}")));
        }
    }
    Ok(())
}

/// Sets every variable of `map` from `tensors[{role}.{name}]`; all must be present with the same shape
/// and finite, else nothing is set.
pub(crate) fn import(role: &str, map: &VarMap, tensors: &HashMap<String, Tensor>) -> Result<()> {
    check(role, map, tensors)?;
    set_checked(role, map, tensors)
}

/// The second half of [`import`]: sets every variable, `tensors` having passed [`check`].
pub(crate) fn set_checked(role: &str, map: &VarMap, tensors: &HashMap<String, Tensor>) -> Result<()> {
    for (name, var) in sorted_vars(map)? {
        var.set(&tensors[&format!("{role}.{name}")].to_dtype(var.dtype())?)?;
    }
    Ok(())
}
