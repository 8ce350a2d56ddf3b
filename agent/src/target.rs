//! Target networks: Polyak averaging between two [`VarMap`]s of the same architecture.
//!
//! The target V-bar has its own `VarMap` whose names equal the online V's (both built from the
//! network's own root), so variables pair by name.

use candle_nn::VarMap;

use crate::error::{Error, Result};
use crate::vars::sorted_vars;

/// theta' <- (1 - tau) theta' + tau theta for every variable: the soft update of Eq. 2.12.
pub fn polyak_update(target: &VarMap, online: &VarMap, tau: f64) -> Result<()> {
    let target = sorted_vars(target)?;
    let online = sorted_vars(online)?;
    if target.len() != online.len() {
        return Err(Error::BadInput(format!("target has {} vars, online {}", target.len(), online.len())));
    }
    for ((tn, t), (on, o)) in target.iter().zip(&online) {
        if tn != on {
            return Err(Error::BadInput(format!("target var {tn} pairs with online var {on}")));
        }
        let mixed = (t.as_tensor().affine(1.0 - tau, 0.0)? + o.as_tensor().affine(tau, 0.0)?)?;
        t.set(&mixed)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use candle_nn::Init;

    #[test]
    fn polyak_mixes_by_tau() {
        let (target, online) = (VarMap::new(), VarMap::new());
        let dev = Device::Cpu;
        target.get((2, 3), "layer0.weight", Init::Const(1.0), DType::F32, &dev).unwrap();
        online.get((2, 3), "layer0.weight", Init::Const(3.0), DType::F32, &dev).unwrap();
        target.get(2, "layer0.bias", Init::Const(-1.0), DType::F32, &dev).unwrap();
        online.get(2, "layer0.bias", Init::Const(0.0), DType::F32, &dev).unwrap();
        polyak_update(&target, &online, 0.01).unwrap();
        let vars = sorted_vars(&target).unwrap();
        let bias = vars[0].1.as_tensor().to_vec1::<f32>().unwrap();
        let weight = vars[1].1.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(bias.iter().all(|&b| (b - (-0.99)).abs() < 1e-7));
        assert!(weight.iter().all(|&w| (w - (0.99 + 0.03)).abs() < 1e-6));
        // The online net is untouched.
        let o =
            sorted_vars(&online).unwrap()[1].1.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(o.iter().all(|&w| w == 3.0));
    }
}
