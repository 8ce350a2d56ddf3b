//! The per-transition part of the update: Q target, TD errors, the three losses and their
//! gradients with respect to the network outputs (seed spec §1.3), in one pass over the rows.
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
    /// Temperature alpha (fixed).
    pub alpha: f64,
    /// Whether log p(a~) is the N(0, I) action prior (else the uniform prior, log p = 0).
    pub normal_prior: bool,
}

/// Per-row inputs of the losses, all from the pre-update forward pass.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowInputs<'a> {
    pub rewards: &'a [f32],
    pub terminated: &'a [f32],
    pub is_weights: Option<&'a [f32]>,
    /// V-bar(s').
    pub next_value: &'a [f32],
    /// Q(s, a) for the batch's actions.
    pub q: &'a [f32],
    /// Q(s, a~) for the policy's fresh actions.
    pub q_pi: &'a [f32],
    /// V(s).
    pub v: &'a [f32],
    /// log pi(a~|s) through the inverse pass.
    pub log_pi: &'a [f32],
    /// a~, `rows x act_dim`.
    pub actions_pi: Mat<'a>,
}

/// Where the output gradients go.
#[derive(Debug)]
pub(crate) struct RowGrads<'a> {
    /// dL/dQ(s, a) of J_Q.
    pub q: &'a mut [f32],
    /// dL/dV(s) of J_V.
    pub v: &'a mut [f32],
    /// dL/dlog pi of the likelihood-ratio loss (y fixed).
    pub log_pi: &'a mut [f32],
    /// Signed TD errors y_q - Q(s, a).
    pub td_errors: &'a mut [f32],
}

/// Evaluates the losses, fills `out` and returns the update's metrics.
///
/// * y_q = scale r + (1 - d) gamma V-bar(s') (Eq. 2.25), delta = y_q - Q(s, a);
///   J_Q = 0.5 mean(w delta^2), dJ_Q/dQ_i = -(delta_i (0.5/B) w_i) 2.
/// * v~ = Q(s, a~) + alpha (log p(a~) - log pi) (Eq. 2.23), J_V = 0.5 mean((V - v~)^2),
///   dJ_V/dV_i = ((V_i - v~_i) (0.5/B)) 2.
/// * adv = alpha (log pi - log p) - Q(s, a~) + V (Eq. 2.27 with the code's sign of V),
///   L_pi = mean(log pi sg(adv)), dL_pi/dlog pi_i = adv_i / B.
pub(crate) fn objective(k: LossScalars, rows: RowInputs, out: RowGrads) -> Metrics {
    let n = rows.q.len();
    let inv_n = (1.0 / n as f64) as f32;
    let half_mean = 0.5 * inv_n;
    let neg_discount = -k.discount;
    let alpha = k.alpha as f32;
    let mut sums = [0.0f32; 7];
    let [q_loss, v_loss, policy_loss, log_pi_sum, q_sum, v_sum, target_sum] = &mut sums;
    for i in 0..n {
        // Q regression (candle: rewards.affine(scale, 0) + next_value * terminated.affine(-g, g)).
        let continuing = rows.terminated[i] * neg_discount + k.discount;
        let target = (rows.rewards[i] * k.scale_reward + 0.0) + rows.next_value[i] * continuing;
        let delta = target - rows.q[i];
        out.td_errors[i] = delta;
        let weight = rows.is_weights.map(|w| w[i]);
        let sq = delta * delta;
        *q_loss += weight.map_or(sq, |w| sq * w);
        let seed = weight.map_or(half_mean, |w| half_mean * w);
        out.q[i] = -((delta * seed) * 2.0);

        // V regression on the policy's soft value.
        let log_prior =
            if k.normal_prior { standard_normal_log_density(rows.actions_pi.row(i)) } else { 0.0 };
        let log_pi = rows.log_pi[i];
        let v_target = rows.q_pi[i] + ((log_prior - log_pi) * alpha + 0.0);
        let v_delta = rows.v[i] - v_target;
        *v_loss += v_delta * v_delta;
        out.v[i] = (v_delta * half_mean) * 2.0;

        // Likelihood-ratio policy loss.
        let advantage = (((log_pi - log_prior) * alpha + 0.0) - rows.q_pi[i]) + rows.v[i];
        *policy_loss += log_pi * advantage;
        out.log_pi[i] = inv_n * advantage;

        *log_pi_sum += log_pi;
        *q_sum += rows.q[i];
        *v_sum += rows.v[i];
        *target_sum += target;
    }
    let mean = |s: f32| s * inv_n;
    Metrics {
        q_loss: mean(sums[0]) * 0.5,
        q2_loss: None,
        v_loss: mean(sums[1]) * 0.5,
        policy_loss: mean(sums[2]),
        temperature_loss: None,
        temperature: alpha,
        mean_log_prob: mean(sums[3]),
        mean_q: mean(sums[4]),
        mean_v: mean(sums[5]),
        mean_q_target: mean(sums[6]),
    }
}
