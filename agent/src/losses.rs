//! The SAC-LSP losses, one function per formula, as `sac/algos/sac.py` @ca39be1 computes them
//! (`docs/sac-lsp.md` §2-§7). Equation numbers are the dissertation's (chapter 2). Every input is
//! `[batch]`;
//! targets are detached here, so each loss trains only the network it names.
//!
//! The temperature alpha multiplies the entropy and action-prior terms. With the paper's settings
//! alpha = 1 and the temperature is carried by `scale_reward` instead.

use candle_core::{Result, Tensor};

/// Q target y_q = scale_reward * r + (1 - done) * gamma * V-bar(s'): the soft Bellman backup of
/// Eq. 2.25 with the code's reward scale; `terminated` is 1.0 for terminal transitions.
pub fn q_target(
    rewards: &Tensor,
    terminated: &Tensor,
    next_value: &Tensor,
    scale_reward: f64,
    discount: f64,
) -> Result<Tensor> {
    let continuing = terminated.affine(-discount, discount)?;
    Ok((rewards.affine(scale_reward, 0.0)? + next_value.mul(&continuing)?)?.detach())
}

/// Signed TD error delta = y_q - Q(s, a) (`docs/sac-lsp.md` §8): the priority signal of prioritized
/// replay.
pub fn td_error(q_target: &Tensor, q: &Tensor) -> Result<Tensor> {
    q_target.sub(&q.detach())
}

/// J_Q = 0.5 mean(w * (y_q - Q(s, a))^2): Eq. 2.25, with the importance-sampling weights w of
/// Eq. 2.32 when the batch came from prioritized replay (only the Q loss is weighted,
/// `docs/sac-lsp.md` §8).
pub fn q_loss(q: &Tensor, q_target: &Tensor, is_weights: Option<&Tensor>) -> Result<Tensor> {
    let sq = q_target.detach().sub(q)?.sqr()?;
    let sq = match is_weights {
        Some(w) => sq.mul(w)?,
        None => sq,
    };
    sq.mean_all()?.affine(0.5, 0.0)
}

/// V target sg(Q(s, a~) - alpha log pi(a~|s) + alpha log p(a~)), a~ ~ pi: the inner expectation of
/// Eq. 2.23 with the code's action prior term.
pub fn v_target(q_pi: &Tensor, log_pi: &Tensor, log_prior: &Tensor, alpha: f64) -> Result<Tensor> {
    let entropy_terms = log_prior.sub(log_pi)?.affine(alpha, 0.0)?;
    Ok(q_pi.add(&entropy_terms)?.detach())
}

/// J_V = 0.5 mean((V(s) - v_target)^2): Eq. 2.23.
pub fn v_loss(v: &Tensor, v_target: &Tensor) -> Result<Tensor> {
    v.sub(&v_target.detach())?.sqr()?.mean_all()?.affine(0.5, 0.0)
}

/// Likelihood-ratio policy loss L = mean(log pi(a~|s) * sg(alpha log pi - Q(s, a~) + V(s) - alpha log p(a~))):
/// its gradient is Eq. 2.27's estimator, with the code's sign of V (the text's "- V" is a typo,
/// `docs/sac-lsp.md` §4) and the action prior. `log_pi` must carry the policy's gradient with a~ held fixed.
pub fn likelihood_ratio_policy_loss(
    log_pi: &Tensor,
    q_pi: &Tensor,
    v: &Tensor,
    log_prior: &Tensor,
    alpha: f64,
) -> Result<Tensor> {
    let kl_terms = log_pi.sub(log_prior)?.affine(alpha, 0.0)?;
    let advantage = kl_terms.sub(q_pi)?.add(v)?.detach();
    log_pi.mul(&advantage)?.mean_all()
}

/// Reparameterised policy loss mean(alpha log pi(a~|s) - Q(s, a~) - alpha log p(a~)) with a~ = tanh(f(z; c))
/// differentiable in the policy (SAC, Haarnoja et al. 2018, Eq. 12; `sac.py` at HEAD). Q must be
/// evaluated with frozen parameters so this loss does not train it.
pub fn reparameterized_policy_loss(
    log_pi: &Tensor,
    q_pi: &Tensor,
    log_prior: &Tensor,
    alpha: f64,
) -> Result<Tensor> {
    log_pi.sub(log_prior)?.affine(alpha, 0.0)?.sub(q_pi)?.mean_all()
}

/// Temperature loss J(alpha) = -mean(log alpha * sg(log pi + target_entropy)) (Haarnoja et al. 2018b,
/// "Soft Actor-Critic Algorithms and Applications", Eq. 18, in softlearning's log-alpha form).
pub fn temperature_loss(log_alpha: &Tensor, log_pi: &Tensor, target_entropy: f64) -> Result<Tensor> {
    let gap = log_pi.detach().affine(1.0, target_entropy)?.mean_all()?;
    log_alpha.squeeze(0)?.mul(&gap)?.neg()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn t(v: &[f64]) -> Tensor {
        Tensor::new(v, &Device::Cpu).unwrap()
    }
    fn val(x: &Tensor) -> f64 {
        x.to_scalar::<f64>().unwrap()
    }

    #[test]
    fn q_target_and_weighted_loss_match_hand_computation() {
        let y = q_target(&t(&[1.0, -2.0]), &t(&[0.0, 1.0]), &t(&[5.0, 7.0]), 10.0, 0.99).unwrap();
        assert_eq!(y.to_vec1::<f64>().unwrap(), vec![10.0 + 0.99 * 5.0, -20.0]);
        let q = t(&[14.0, -19.0]);
        let l = q_loss(&q, &y, Some(&t(&[2.0, 0.5]))).unwrap();
        let d0: f64 = 14.95 - 14.0;
        assert!((val(&l) - 0.5 * (2.0 * d0 * d0 + 0.5 * 1.0) / 2.0).abs() < 1e-12);
        assert_eq!(td_error(&y, &q).unwrap().to_vec1::<f64>().unwrap()[1], -1.0);
    }

    #[test]
    fn likelihood_ratio_gradient_is_log_pi_gradient_times_advantage() {
        let lp = Var::new(&[-1.0f64, -2.0], &Device::Cpu).unwrap();
        let (q, v, prior) = (t(&[3.0, 1.0]), t(&[0.5, 0.25]), t(&[-0.5, -1.0]));
        let loss = likelihood_ratio_policy_loss(lp.as_tensor(), &q, &v, &prior, 1.0).unwrap();
        let g = loss.backward().unwrap().get(&lp).unwrap().to_vec1::<f64>().unwrap();
        // advantage_i = log pi - Q + V - log p; d/dlogpi of mean(logpi * sg(adv)) = adv / n.
        assert!((g[0] - (-1.0 - 3.0 + 0.5 + 0.5) / 2.0).abs() < 1e-12);
        assert!((g[1] - (-2.0 - 1.0 + 0.25 + 1.0) / 2.0).abs() < 1e-12);
    }

    #[test]
    fn temperature_loss_pushes_alpha_up_when_entropy_is_too_low() {
        let log_alpha = Var::new(&[0.0f64], &Device::Cpu).unwrap();
        // log pi = 2 (entropy -2) below a target entropy of 0: alpha must grow, gradient negative.
        let loss = temperature_loss(log_alpha.as_tensor(), &t(&[2.0, 2.0]), 0.0).unwrap();
        let g = loss.backward().unwrap().get(&log_alpha).unwrap().to_vec1::<f64>().unwrap();
        assert_eq!(g, vec![-2.0]);
    }
}
