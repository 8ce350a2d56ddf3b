//! Log-densities of the latent-space policy (`docs/sac-lsp.md` §1): the latent prior, the tanh
//! squash correction, and the action prior. Each takes `[batch, dim]` and returns `[batch]`.

use candle_core::{Result, Tensor};

use crate::config::ActionPrior;

/// Epsilon inside the squash correction, as `latent_space_policy.py` adds it.
pub const SQUASH_EPSILON: f64 = 1e-6;

/// log N(x; 0, I) = -|x|^2 / 2 - (D / 2) log(2 pi): the latent prior p(z) (`docs/sac-lsp.md` §1), also the
/// 'normal' action prior.
pub fn standard_normal_log_density(x: &Tensor) -> Result<Tensor> {
    let d = x.dim(1)? as f64;
    x.sqr()?.sum(1)?.affine(-0.5, -0.5 * d * (2.0 * std::f64::consts::PI).ln())
}

/// sum_j log(1 - tanh(y_j)^2 + eps): log |det da/dy| of the squash a = tanh(y), with the code's
/// epsilon (`docs/sac-lsp.md` §1); subtracted from the pre-squash log-density.
pub fn tanh_log_det_jacobian(y: &Tensor) -> Result<Tensor> {
    y.tanh()?.sqr()?.affine(-1.0, 1.0 + SQUASH_EPSILON)?.log()?.sum(1)
}

/// log pi(a|s) = log N(z) - log|det df/dz| - (if squashing) sum_j log(1 - tanh(y_j)^2 + eps): the change of
/// variables through the bijector y = f(z; c) and the squash (`docs/sac-lsp.md` §1).
pub fn policy_log_density(z: &Tensor, bijector_log_det: &Tensor, y: &Tensor, squash: bool) -> Result<Tensor> {
    let log_py = (standard_normal_log_density(z)? - bijector_log_det)?;
    if squash { log_py - tanh_log_det_jacobian(y)? } else { Ok(log_py) }
}

/// log p(a) of the action prior (`docs/sac-lsp.md` §5): N(0, I) on the action the Q net sees (squashed
/// if the level
/// squashes, the latent h for a higher level), or 0 for the uniform prior.
pub fn action_prior_log_density(prior: ActionPrior, action: &Tensor) -> Result<Tensor> {
    match prior {
        ActionPrior::Normal => standard_normal_log_density(action),
        ActionPrior::Uniform => action.zeros_like()?.sum(1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn normal_density_matches_closed_form() {
        let x = Tensor::new(&[[0.0f64, 0.0], [1.0, -2.0]], &Device::Cpu).unwrap();
        let got = standard_normal_log_density(&x).unwrap().to_vec1::<f64>().unwrap();
        let c = -(2.0 * std::f64::consts::PI).ln();
        assert!((got[0] - c).abs() < 1e-12 && (got[1] - (c - 2.5)).abs() < 1e-12);
    }

    #[test]
    fn squash_correction_is_log_of_tanh_derivative() {
        let y = Tensor::new(&[[0.3f64, -1.2]], &Device::Cpu).unwrap();
        let got = tanh_log_det_jacobian(&y).unwrap().to_vec1::<f64>().unwrap()[0];
        let want: f64 = [0.3f64, -1.2].iter().map(|v| (1.0 - v.tanh().powi(2) + 1e-6).ln()).sum();
        assert!((got - want).abs() < 1e-12);
    }
}
