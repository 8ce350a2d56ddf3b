//! The losses of a categorical critic (`docs/sac-lsp.md` §13), in its two variants. Each returns
//! the Q and V losses and the two values the policy loss reads, so [`Learner`](crate::Learner)
//! runs the same policy update over every critic.

use candle_core::{D, Device, Result, Tensor};

use crate::batch::{Batch, BatchTensors};
use crate::categorical::{Brackets, Support};
use crate::config::{AgentConfig, CategoricalVariant};
use crate::networks::Networks;

/// What the critic's losses hand the rest of the update.
pub(crate) struct CriticLosses {
    /// J_Q of each Q net.
    pub q_losses: Vec<Tensor>,
    /// J_V.
    pub v_loss: Tensor,
    /// The Q(s, a~) the policy loss uses (gradient to a~ only, for the reparameterised loss).
    pub policy_q: Tensor,
    /// The V(s) the policy loss uses, detached.
    pub policy_v: Tensor,
}

/// The policy samples and their densities, as the update drew them.
pub(crate) struct PolicyTerms<'a> {
    /// a~ ~ pi(.|s), `[batch, act_dim]`.
    pub actions: &'a Tensor,
    /// log pi(a~|s), `[batch]`.
    pub log_pi: &'a Tensor,
    /// log p(a~), `[batch]`.
    pub log_prior: &'a Tensor,
    /// The temperature alpha.
    pub alpha: f64,
}

fn rows(t: &Tensor) -> Result<Vec<f32>> {
    t.detach().flatten_all()?.to_vec1()
}

/// The categorical critic's losses for `cfg`'s variant.
pub(crate) fn categorical_losses(
    nets: &Networks,
    cfg: &AgentConfig,
    batch: &Batch,
    b: &BatchTensors,
    pi: &PolicyTerms,
    q_pi_mean: &Tensor,
    v_mean: &Tensor,
) -> Result<CriticLosses> {
    // The Q target moves V-bar's atoms to scale r + gamma^n (1 - d) z_j.
    let gamma = f64::from(cfg.bootstrap_discount());
    let inputs = Inputs {
        nets,
        support: Support::new(&cfg.categorical),
        b,
        pi,
        shifts: batch.rewards.iter().map(|r| f64::from(cfg.scale_reward * r)).collect(),
        scales: batch.terminated.iter().map(|d| gamma * (1.0 - f64::from(*d))).collect(),
    };
    match cfg.categorical.variant {
        CategoricalVariant::SoftC51 => soft_c51(&inputs, q_pi_mean, v_mean),
        CategoricalVariant::Dissertation => dissertation(&inputs),
    }
}

/// What both variants read: the networks, the support, the batch, the policy's samples, and the
/// Q target's move of the atoms, z_j -> shifts_i + scales_i z_j per row i.
struct Inputs<'a> {
    nets: &'a Networks,
    support: Support,
    b: &'a BatchTensors,
    pi: &'a PolicyTerms<'a>,
    /// scale r per row.
    shifts: Vec<f64>,
    /// gamma^n (1 - d) per row.
    scales: Vec<f64>,
}

/// Cross-entropy -sum_i m_i log p_i per row of `[rows, atoms]`, IS-weighted, averaged.
pub(crate) fn cross_entropy(target: &Tensor, log_probs: &Tensor, weights: Option<&Tensor>) -> Result<Tensor> {
    let per_row = target.detach().mul(log_probs)?.sum(D::Minus1)?.neg()?;
    match weights {
        Some(w) => per_row.mul(w)?.mean_all(),
        None => per_row.mean_all(),
    }
}

/// Soft C51: Q's distribution learns the projection of V-bar(s')'s atoms moved to
/// scale r + gamma^n (1 - d) z_j; V's learns the projection of Q(s, a~)'s atoms moved by the
/// entropy terms alpha (log p(a~) - log pi(a~|s)), a~ ~ pi: the soft Bellman backup of the
/// scalar critic applied atom by atom (for a point mass, the scalar targets exactly). Both by
/// cross-entropy; the policy reads the distributions' means.
fn soft_c51(inputs: &Inputs, q_pi_mean: &Tensor, v_mean: &Tensor) -> Result<CriticLosses> {
    let Inputs { nets, support, b, pi, shifts, scales } = inputs;
    let (n, atoms, dev) = (shifts.len(), support.atoms(), &Device::Cpu);
    let next = rows(&nets.v_target.model.probs(&b.next_observations)?)?;
    let q_target = Tensor::from_vec(support.project(&next, shifts, scales), (n, atoms), dev)?;
    let q_losses = nets
        .qs
        .iter()
        .map(|q| {
            cross_entropy(&q_target, &q.model.log_probs(&b.observations, &b.actions)?, b.is_weights.as_ref())
        })
        .collect::<Result<Vec<_>>>()?;

    let q_pi = rows(&nets.qs[0].model.probs(&b.observations, pi.actions, true)?)?;
    let entropy: Vec<f32> = rows(&pi.log_prior.sub(pi.log_pi)?)?;
    let v_shifts: Vec<f64> = entropy.iter().map(|e| pi.alpha * f64::from(*e)).collect();
    let v_target = Tensor::from_vec(support.project(&q_pi, &v_shifts, &vec![1.0; n]), (n, atoms), dev)?;
    let v_loss = cross_entropy(&v_target, &nets.v.model.log_probs(&b.observations)?, None)?;
    Ok(CriticLosses { q_losses, v_loss, policy_q: q_pi_mean.clone(), policy_v: v_mean.detach() })
}

/// The dissertation code's sum over the moved atoms, f(p) = sum_j (u_j - b_j) log p[l_j] +
/// (b_j - l_j) log p[u_j], with p clipped to [1e-10, 1] as `project_TZ` does; `[rows]`.
fn bracket_sum(brackets: &Brackets, probs: &Tensor) -> Result<Tensor> {
    let shape = probs.dims2()?;
    let dev = &Device::Cpu;
    let index = |v: &[u32]| Tensor::from_slice(v, shape, dev);
    let weight = |v: &[f32]| Tensor::from_slice(v, shape, dev);
    let log_at = |idx: &[u32]| probs.gather(&index(idx)?, 1)?.clamp(1e-10f32, 1.0f32)?.log();
    let lower = log_at(&brackets.lower)?.mul(&weight(&brackets.lower_weight)?)?;
    let upper = log_at(&brackets.upper)?.mul(&weight(&brackets.upper_weight)?)?;
    lower.add(&upper)?.sum(D::Minus1)
}

/// The dissertation's formulation exactly as `sac-c51/sac/algos/sac.py` ran it (seed-impl §2.3,
/// dissertation Eq. 3.1-3.2): every distribution p is turned into the scalar f(p) of
/// [`bracket_sum`], always with the batch's rewards and terminals; Q regresses -f(Z(s, a)) on
/// scale r + gamma (1 - d) f(V-bar(s')), V regresses f(V(s)) on f(Q(s, a~)) - log pi + log p, and the
/// policy's likelihood ratio uses f(Q(s, a~)) and f(V(s)) in place of Q and V. f is not an
/// expectation of anything, which is why the variant cannot learn; it is kept to reproduce that.
fn dissertation(inputs: &Inputs) -> Result<CriticLosses> {
    let Inputs { nets, support, b, pi, shifts, scales } = inputs;
    let brackets = support.dissertation_brackets(shifts, scales);
    let dev = &Device::Cpu;
    let next = bracket_sum(&brackets, &nets.v_target.model.probs(&b.next_observations)?)?.detach();
    let scale_r = Tensor::from_vec(shifts.iter().map(|s| *s as f32).collect::<Vec<_>>(), shifts.len(), dev)?;
    let gamma_not_done =
        Tensor::from_vec(scales.iter().map(|s| *s as f32).collect::<Vec<_>>(), scales.len(), dev)?;
    let ys = scale_r.add(&next.mul(&gamma_not_done)?)?.detach();
    let q_losses = nets
        .qs
        .iter()
        .map(|q| {
            let critic =
                bracket_sum(&brackets, &q.model.probs(&b.observations, &b.actions, false)?)?.neg()?;
            crate::losses::q_loss(&critic, &ys, b.is_weights.as_ref())
        })
        .collect::<Result<Vec<_>>>()?;
    let v = bracket_sum(&brackets, &nets.v.model.probs(&b.observations)?)?;
    let q_pi = bracket_sum(&brackets, &nets.qs[0].model.probs(&b.observations, pi.actions, true)?)?;
    let v_target = crate::losses::v_target(&q_pi, pi.log_pi, pi.log_prior, pi.alpha)?;
    let v_loss = crate::losses::v_loss(&v, &v_target)?;
    Ok(CriticLosses { q_losses, v_loss, policy_q: q_pi, policy_v: v.detach() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Var;

    #[test]
    fn cross_entropy_gradient_matches_finite_differences() {
        // Loss of logits x against a fixed target m: d/dx_k = sum_i m_i (softmax_k - [i == k]).
        let dev = &Device::Cpu;
        let logits = [0.3f64, -1.2, 2.0, 0.1, 0.7, -0.4];
        // Two rows of three atoms.
        let target = Tensor::new(&[[0.2f64, 0.3, 0.5], [0.0, 0.5, 0.5]], dev).unwrap();
        let weights = Tensor::new(&[2.0f64, 0.5], dev).unwrap();
        let loss_at = |x: &[f64]| -> f64 {
            let t = Tensor::from_slice(x, (2, 3), dev).unwrap();
            let lp = candle_nn::ops::log_softmax(&t, D::Minus1).unwrap();
            cross_entropy(&target, &lp, Some(&weights)).unwrap().to_scalar::<f64>().unwrap()
        };
        let var = Var::from_tensor(&Tensor::from_slice(&logits, (2, 3), dev).unwrap()).unwrap();
        let lp = candle_nn::ops::log_softmax(var.as_tensor(), D::Minus1).unwrap();
        let loss = cross_entropy(&target, &lp, Some(&weights)).unwrap();
        let grad =
            loss.backward().unwrap().get(&var).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let h = 1e-6;
        for k in 0..6 {
            let (mut up, mut down) = (logits, logits);
            up[k] += h;
            down[k] -= h;
            let numeric = (loss_at(&up) - loss_at(&down)) / (2.0 * h);
            assert!((numeric - grad[k]).abs() < 1e-6, "logit {k}: {numeric} vs {}", grad[k]);
        }
    }

    #[test]
    fn bracket_sum_is_the_codes_weighted_log_likelihood() {
        let support = Support::new(&crate::config::CategoricalConfig {
            atoms: 3,
            v_min: 0.0,
            v_max: 2.0,
            ..Default::default()
        });
        // shift 0.5, scale 0: every atom moves to 0.5, b = 0.5: f = sum_j 0.5 log p0 + 0.5 log p1.
        let brackets = support.dissertation_brackets(&[0.5], &[0.0]);
        let p = Tensor::new(&[[0.2f32, 0.3, 0.5]], &Device::Cpu).unwrap();
        let f = bracket_sum(&brackets, &p).unwrap().to_vec1::<f32>().unwrap()[0];
        let expected = 3.0 * (0.5 * 0.2f32.ln() + 0.5 * 0.3f32.ln());
        assert!((f - expected).abs() < 1e-5, "{f} vs {expected}");
    }
}
