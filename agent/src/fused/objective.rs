//! The per-transition part of the update: Q target, TD errors, the three losses and their
//! gradients with respect to the network outputs (`docs/sac-lsp.md` §2-§7), in one pass over the rows.
//!
//! Each value is rounded the way candle evaluates `losses.rs` and differentiates it: the scalar
//! factors are candle's `affine` constants (f64 cast to f32), and the output gradients follow its
//! backward chain (0.5 from the loss, 1/B from `mean_all`, then `sqr`'s (x g) 2), so the fused and
//! candle updates start their backward passes from the same numbers.

use crate::learning::Metrics;

use super::flow::standard_normal_log_density;
use super::linalg::Mat;

/// The scalar hyperparameters the losses use.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LossScalars {
    /// Reward scale (inside the Q target only).
    pub scale_reward: f32,
    /// gamma.
    pub discount: f32,
    /// Temperature alpha of this update.
    pub alpha: f64,
    /// Whether log p(a~) is the N(0, I) action prior (else the uniform prior, log p = 0).
    pub normal_prior: bool,
    /// The reparameterised policy loss instead of the likelihood-ratio one.
    pub reparameterize: bool,
    /// With a learned temperature: (log alpha, the target entropy).
    pub temperature: Option<(f32, f32)>,
}

/// Per-row inputs of the losses, all from the pre-update forward pass.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowInputs<'a> {
    pub rewards: &'a [f32],
    pub terminated: &'a [f32],
    pub is_weights: Option<&'a [f32]>,
    /// V-bar(s').
    pub next_value: &'a [f32],
    /// Each Q's output over two rows per transition: Q(s, a) for the batch's actions in rows
    /// `..n`, Q(s, a~) for the policy's fresh actions in rows `n..2n`. Q1 first.
    pub qs: &'a [&'a [f32]],
    /// V(s).
    pub v: &'a [f32],
    /// log pi(a~|s).
    pub log_pi: &'a [f32],
    /// a~, `rows x act_dim`.
    pub actions_pi: Mat<'a>,
}

/// Where the output gradients go.
#[derive(Debug)]
pub(crate) struct RowGrads<'a, 'b> {
    /// Per Q, over its two rows per transition: dJ_Q/dQ(s, a) in rows `..n`; with the
    /// reparameterised loss, dL_pi/dQ(s, a~) in rows `n..2n` (through min(Q1, Q2)).
    pub qs: &'b mut [&'a mut [f32]],
    /// dL/dV(s) of J_V.
    pub v: &'a mut [f32],
    /// dL_pi/dlog pi (likelihood ratio: y fixed; reparameterised: z fixed).
    pub log_pi: &'a mut [f32],
    /// Signed TD errors y_q - Q1(s, a).
    pub td_errors: &'a mut [f32],
}

/// What [`objective`] returns besides the row gradients.
#[derive(Clone, Debug)]
pub(crate) struct Objective {
    pub metrics: Metrics,
    /// dL/dlog alpha of the temperature loss, when it is learned.
    pub log_alpha_grad: Option<f32>,
    /// dL_pi/dlog p(a~) of the reparameterised loss (the same for every row), else 0.
    pub log_prior_grad: f32,
}

/// Evaluates the losses, fills `out` and returns the update's metrics.
///
/// * y_q = scale r + (1 - d) gamma V-bar(s') (Eq. 2.25), delta_k = y_q - Q_k(s, a);
///   J_Qk = 0.5 mean(w delta_k^2), dJ_Qk/dQ_k,i = -(delta_k,i (0.5/B) w_i) 2.
/// * Q~ = min_k Q_k(s, a~) (clipped double Q; Q1 alone without twin Q);
///   v~ = Q~ + alpha (log p(a~) - log pi) (Eq. 2.23), J_V = 0.5 mean((V - v~)^2),
///   dJ_V/dV_i = ((V_i - v~_i) (0.5/B)) 2.
/// * Likelihood ratio: adv = alpha (log pi - log p) - Q1(s, a~) + V (Eq. 2.27 with the code's
///   sign of V), L_pi = mean(log pi sg(adv)), dL_pi/dlog pi_i = adv_i / B.
/// * Reparameterised: L_pi = mean(alpha (log pi - log p) - Q~), so dL_pi/dlog pi = alpha / B,
///   dL_pi/dlog p = -alpha / B, and -1/B to each Q that attains the minimum (candle's
///   `minimum` sends the gradient to both on a tie).
/// * Learned temperature: J(alpha) = -log alpha mean(log pi + H), dJ/dlog alpha = -mean(log pi + H).
pub(crate) fn objective(k: LossScalars, rows: RowInputs, out: RowGrads) -> Objective {
    let n = rows.v.len();
    let inv_n = (1.0 / n as f64) as f32;
    let half_mean = 0.5 * inv_n;
    let neg_discount = -k.discount;
    let alpha = k.alpha as f32;
    let alpha_inv_n = inv_n * alpha;
    let target_entropy = k.temperature.map_or(0.0, |(_, h)| h);
    let mut q_losses = [0.0f32; 2];
    let mut sums = [0.0f32; 7];
    let [v_loss, policy_loss, log_pi_sum, q_sum, v_sum, target_sum, entropy_gap] = &mut sums;
    for i in 0..n {
        // Q regression (candle: rewards.affine(scale, 0) + next_value * terminated.affine(-g, g)).
        let continuing = rows.terminated[i] * neg_discount + k.discount;
        let target = (rows.rewards[i] * k.scale_reward + 0.0) + rows.next_value[i] * continuing;
        let weight = rows.is_weights.map(|w| w[i]);
        let seed = weight.map_or(half_mean, |w| half_mean * w);
        let mut q_pi_min = f32::INFINITY;
        for ((q, grad), loss) in rows.qs.iter().zip(out.qs.iter_mut()).zip(&mut q_losses) {
            let delta = target - q[i];
            let sq = delta * delta;
            *loss += weight.map_or(sq, |w| sq * w);
            grad[i] = -((delta * seed) * 2.0);
            q_pi_min = q_pi_min.min(q[n + i]);
        }
        out.td_errors[i] = target - rows.qs[0][i];

        // V regression on the policy's soft value.
        let log_prior =
            if k.normal_prior { standard_normal_log_density(rows.actions_pi.row(i)) } else { 0.0 };
        let log_pi = rows.log_pi[i];
        let v_target = q_pi_min + ((log_prior - log_pi) * alpha + 0.0);
        let v_delta = rows.v[i] - v_target;
        *v_loss += v_delta * v_delta;
        out.v[i] = (v_delta * half_mean) * 2.0;

        if k.reparameterize {
            *policy_loss += ((log_pi - log_prior) * alpha + 0.0) - q_pi_min;
            out.log_pi[i] = alpha_inv_n;
            for (q, grad) in rows.qs.iter().zip(out.qs.iter_mut()) {
                grad[n + i] = if q[n + i] == q_pi_min { -inv_n } else { 0.0 };
            }
        } else {
            let advantage = (((log_pi - log_prior) * alpha + 0.0) - rows.qs[0][n + i]) + rows.v[i];
            *policy_loss += log_pi * advantage;
            out.log_pi[i] = inv_n * advantage;
        }

        *log_pi_sum += log_pi;
        *q_sum += rows.qs[0][i];
        *v_sum += rows.v[i];
        *target_sum += target;
        *entropy_gap += log_pi + target_entropy;
    }
    let mean = |s: f32| s * inv_n;
    let gap = mean(sums[6]);
    let metrics = Metrics {
        q_loss: mean(q_losses[0]) * 0.5,
        q2_loss: (rows.qs.len() > 1).then(|| mean(q_losses[1]) * 0.5),
        v_loss: mean(sums[0]) * 0.5,
        policy_loss: mean(sums[1]),
        temperature_loss: k.temperature.map(|(log_alpha, _)| -(log_alpha * gap)),
        temperature: alpha,
        mean_log_prob: mean(sums[2]),
        mean_q: mean(sums[3]),
        mean_v: mean(sums[4]),
        mean_q_target: mean(sums[5]),
    };
    Objective {
        metrics,
        log_alpha_grad: k.temperature.map(|_| -gap),
        log_prior_grad: if k.reparameterize { -alpha_inv_n } else { 0.0 },
    }
}
