//! The fused update: [`Learner::update`](crate::Learner::update)'s maths (seed spec §1.3) on the
//! arena, with every intermediate in a [`Workspace`] allocated once per batch size.
//!
//! Order of work (all from the pre-update parameters, as `sac.py`'s single `session.run`):
//! 1. one GEMM s [W_V0; W_E0; W_Q0,obs]^T for the three first layers that read s;
//! 2. V-bar(s') -> y_q; V(s); the embedding c = E(s);
//! 3. y = f(z; c), a~ = tanh(y); Q on [a; a~] as one 2B-row batch (shared observation product);
//! 4. the inverse pass z = f^-1(y; c) -> log pi (y fixed);
//! 5. losses and output gradients (`objective.rs`);
//! 6. backward: Q on the B batch rows, V, the bijector then the embedding, and one GEMM for the
//!    three first-layer weight gradients; no input gradients of first layers, no Q gradients
//!    from the policy loss (the likelihood-ratio loss does not reach Q);
//! 7. Adam, array by array as each gradient becomes final during step 6 (`adam.rs`'s
//!    [`Trainable`](super::adam::Trainable)); then V-bar <- (1 - tau) V-bar + tau V.

use crate::batch::Batch;
use crate::config::AgentConfig;
use crate::learning::{UpdateOutput, fill_latent_noise};

use super::FusedLearner;
use super::adam::{AdamStep, Trainable, polyak};
use super::dense::Activation::{self, Linear, Relu};
use super::dense::{
    MlpBufs, Net, backward_to_first, bias, bias_act_from, forward, forward_rest, sum_bias_act,
};
use super::flow::{self, Flow, FlowBufs};
use super::layout::{Layout, PolyakPair, Role};
use super::linalg::{Mat, MatMut, VectorKernel, vectorized};
use super::objective::{LossScalars, RowGrads, RowInputs, objective};

/// Every intermediate of one update for `rows` transitions.
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    rows: usize,
    /// s [W_V0; W_E0; W_Q0,obs]^T, `rows x obs.rows`.
    obs_pre: Vec<f32>,
    /// The three first layers' pre-activation gradients, same layout.
    obs_grad: Vec<f32>,
    v_target: MlpBufs,
    v: MlpBufs,
    /// Q on 2 rows per transition: (s, a) in the top half, (s, a~) in the bottom half.
    q: MlpBufs,
    /// [a; a~], `2 rows x act_dim`.
    q_actions: Vec<f32>,
    embedding: MlpBufs,
    pub(super) flow: FlowBufs,
    z: Vec<f32>,
    log_pi_grad: Vec<f32>,
}

impl Workspace {
    /// Buffers for `rows` transitions.
    pub(crate) fn new(cfg: &AgentConfig, layout: &Layout, rows: usize) -> Self {
        let context = layout.embedding.widths().last().copied().unwrap_or(0);
        Self {
            rows,
            obs_pre: vec![0.0; rows * layout.obs.rows],
            obs_grad: vec![0.0; rows * layout.obs.rows],
            v_target: MlpBufs::new(&layout.v_target.widths(), rows, false),
            v: MlpBufs::new(&layout.v.widths(), rows, true),
            q: MlpBufs::new(&layout.q.widths(), 2 * rows, true),
            q_actions: vec![0.0; 2 * rows * cfg.act_dim],
            embedding: MlpBufs::new(&layout.embedding.widths(), rows, true),
            flow: FlowBufs::new(&layout.couplings, rows, cfg.act_dim, context),
            z: vec![0.0; rows * cfg.act_dim],
            log_pi_grad: vec![0.0; rows],
        }
    }

    /// Number of transitions the buffers hold.
    pub(crate) fn rows(&self) -> usize {
        self.rows
    }
}

/// The embedding's output activation.
fn embedding_output(cfg: &AgentConfig) -> Activation {
    if cfg.embedding_output_relu { Relu } else { Linear }
}

/// Columns `from .. from + n` of the `rows x width` first-layer gradient block.
fn block(obs_grad: &mut [f32], rows: usize, width: usize, from: usize, n: usize) -> MatMut<'_> {
    MatMut::strided(obs_grad, rows, width, width).columns(from, n)
}

/// The MLPs of a level with their activations.
struct Nets<'a> {
    v_target: Net<'a>,
    v: Net<'a>,
    q: Net<'a>,
    embedding: Net<'a>,
}

fn nets<'a>(lay: &'a Layout, cfg: &AgentConfig) -> Nets<'a> {
    let critic = |at| Net { at, hidden: Relu, output: Linear };
    Nets {
        v_target: critic(&lay.v_target),
        v: critic(&lay.v),
        q: critic(&lay.q),
        embedding: Net { at: &lay.embedding, hidden: Relu, output: embedding_output(cfg) },
    }
}

impl FusedLearner {
    /// Steps 1-4: every forward value the losses need, into the workspace.
    fn forward_pass(&mut self, batch: &Batch) {
        let (cfg, lay, gemm, p) = (&self.cfg, &self.layout, &self.gemm, &self.params);
        let Nets { v_target, v, q, embedding } = nets(lay, cfg);
        let flow = Flow { couplings: &lay.couplings, tanh: self.tanh };
        let w = &mut self.work;
        let (b, o, d, width) = (batch.size, cfg.obs_dim, cfg.act_dim, lay.obs.rows);
        let s = Mat::dense(&batch.observations, b, o);
        let stacked = Mat::dense(&p[lay.obs.weight..lay.obs.weight + width * o], width, o);
        gemm.mul(&mut MatMut::dense(&mut w.obs_pre, b, width), s, stacked.t(), false);
        let pre = Mat::dense(&w.obs_pre, b, width);

        forward(gemm, p, v_target, &mut w.v_target, Mat::dense(&batch.next_observations, b, o));

        let first = &lay.v.layers[0];
        bias_act_from(&mut w.v.act_mut(0, b), pre.columns(lay.obs.v, first.out), bias(p, first), Relu);
        forward_rest(gemm, p, v, &mut w.v, b);

        let first = &lay.embedding.layers[0];
        let e_pre = pre.columns(lay.obs.embedding, first.out);
        bias_act_from(&mut w.embedding.act_mut(0, b), e_pre, bias(p, first), Relu);
        forward_rest(gemm, p, embedding, &mut w.embedding, b);

        fill_latent_noise(self.seed, self.step, &mut w.z[..b * d]);
        flow::sample(gemm, p, flow, &mut w.flow, &w.z, w.embedding.output(b));
        w.q_actions[..b * d].copy_from_slice(&batch.actions);
        // libm's tanh, as candle, for the squash whatever the nets use (see `tanh.rs`).
        let a = &mut w.q_actions[b * d..2 * b * d];
        for (a, y) in a.iter_mut().zip(&w.flow.y) {
            *a = if cfg.squash { y.tanh() } else { *y };
        }

        // Q's first layer: per-input products summed, then the bias (mlp.rs's Dense order); the
        // observation product is shared by both halves.
        let first = &lay.q.layers[0];
        let h = first.out;
        let action_weight = Mat::dense(&p[lay.q_action_weight..lay.q_action_weight + h * d], h, d);
        gemm.mul(&mut w.q.act_mut(0, 2 * b), Mat::dense(&w.q_actions, 2 * b, d), action_weight.t(), false);
        let (top, bottom) = w.q.acts[0].split_at_mut(b * h);
        let obs_part = pre.columns(lay.obs.q, h);
        sum_bias_act(&mut MatMut::dense(top, b, h), obs_part, bias(p, first), Relu);
        sum_bias_act(&mut MatMut::dense(&mut bottom[..b * h], b, h), obs_part, bias(p, first), Relu);
        forward_rest(gemm, p, q, &mut w.q, 2 * b);

        let squashed = cfg.squash.then(|| &w.q_actions[b * d..2 * b * d]);
        flow::inverse(gemm, p, flow, &mut w.flow, w.embedding.output(b), squashed, true);
    }

    /// Steps 6-7: every trained gradient into `self.grads`; with `step`, Adam on each array as soon
    /// as its gradient is final, then the Polyak average of V-bar.
    fn backward_pass(&mut self, batch: &Batch, step: bool) {
        // This update's Adam scalars per network (their step counts advance at the end).
        let steps = step.then(|| self.adam_steps.map(|t| AdamStep::new(&self.adam, t + 1)));
        let step_of = |role: Role| Some(steps?[role.adam_index()?]);
        let (cfg, lay, gemm, w) = (&self.cfg, &self.layout, &self.gemm, &mut self.work);
        let Nets { v, q, embedding, .. } = nets(lay, cfg);
        let flow = Flow { couplings: &lay.couplings, tanh: self.tanh };
        let mut train = Trainable::new(&mut self.params, &mut self.grads, &mut self.adam_m, &mut self.adam_v);
        let (b, o, d, width) = (batch.size, cfg.obs_dim, cfg.act_dim, lay.obs.rows);

        train.set_step(step_of(Role::Q));
        let h = lay.q.layers[0].out;
        backward_to_first(
            gemm,
            &mut train,
            q,
            &mut w.q,
            b,
            Some(block(&mut w.obs_grad, b, width, lay.obs.q, h)),
        );
        let g0 = Mat::dense(&w.obs_grad, b, width).columns(lay.obs.q, h);
        let mut dw = train.grad_matrix(lay.q_action_weight, h, d);
        gemm.mul(&mut dw, g0.t(), Mat::dense(&batch.actions, b, d), false);
        train.finished(lay.q_action_weight, h * d);

        train.set_step(step_of(Role::V));
        let h = lay.v.layers[0].out;
        backward_to_first(
            gemm,
            &mut train,
            v,
            &mut w.v,
            b,
            Some(block(&mut w.obs_grad, b, width, lay.obs.v, h)),
        );

        train.set_step(step_of(Role::Policy));
        let mut dc = w.embedding.output_grad_mut(b);
        flow::backward(gemm, &mut train, flow, &mut w.flow, &w.log_pi_grad[..b], &mut dc);
        let h = lay.embedding.layers[0].out;
        let first = Some(block(&mut w.obs_grad, b, width, lay.obs.embedding, h));
        backward_to_first(gemm, &mut train, embedding, &mut w.embedding, b, first);

        // The stacked first layer: one weight-gradient GEMM, then each network's part.
        let s = Mat::dense(&batch.observations, b, o);
        let mut dw = train.grad_matrix(lay.obs.weight, width, o);
        gemm.mul(&mut dw, Mat::dense(&w.obs_grad, b, width).t(), s, false);
        for (role, layer) in [
            (Role::V, &lay.v.layers[0]),
            (Role::Policy, &lay.embedding.layers[0]),
            (Role::Q, &lay.q.layers[0]),
        ] {
            train.set_step(step_of(role));
            train.finished(layer.weight, layer.out * o);
        }

        if step {
            vectorized(Polyak { params: train.params_mut(), pairs: &lay.polyak, tau: cfg.tau.into() });
            for t in &mut self.adam_steps {
                *t += 1;
            }
        }
    }

    /// One update from `batch` (validated by the caller), returning the metrics and TD errors.
    pub(super) fn update_validated(&mut self, batch: &Batch) -> UpdateOutput {
        let out = self.losses(batch);
        self.backward_pass(batch, true);
        self.step += 1;
        out
    }

    /// Steps 1-6: the losses, TD errors and every gradient (into `self.grads`), no parameter change.
    #[cfg(test)]
    pub(super) fn compute_gradients(&mut self, batch: &Batch) -> UpdateOutput {
        let out = self.losses(batch);
        self.backward_pass(batch, false);
        out
    }

    /// Steps 1-5: forward pass, losses, TD errors and the output gradients.
    fn losses(&mut self, batch: &Batch) -> UpdateOutput {
        let b = batch.size;
        if self.work.rows() != b {
            self.work = Workspace::new(&self.cfg, &self.layout, b);
        }
        self.forward_pass(batch);
        let cfg = &self.cfg;
        let scalars = LossScalars {
            scale_reward: cfg.scale_reward,
            discount: cfg.discount,
            alpha: cfg.initial_temperature.into(),
            normal_prior: cfg.action_prior == crate::config::ActionPrior::Normal,
        };
        let w = &mut self.work;
        let mut td_errors = vec![0.0; b];
        // The critics end in one unit, so their last buffers are plain per-row columns.
        let (last_q, last_v) = (w.q.acts.len() - 1, w.v.acts.len() - 1);
        let q_out = &w.q.acts[last_q];
        let metrics = objective(
            scalars,
            RowInputs {
                rewards: &batch.rewards,
                terminated: &batch.terminated,
                is_weights: batch.is_weights.as_deref(),
                next_value: &w.v_target.acts[w.v_target.acts.len() - 1][..b],
                q: &q_out[..b],
                q_pi: &q_out[b..2 * b],
                v: &w.v.acts[last_v][..b],
                log_pi: &w.flow.log_pi[..b],
                actions_pi: Mat::dense(&w.q_actions[b * cfg.act_dim..], b, cfg.act_dim),
            },
            RowGrads {
                q: &mut w.q.grads[last_q][..b],
                v: &mut w.v.grads[last_v][..b],
                log_pi: &mut w.log_pi_grad[..b],
                td_errors: &mut td_errors,
            },
        );

        UpdateOutput { metrics, td_errors }
    }
}

/// V-bar <- (1 - tau) V-bar + tau V over every array pair, vectorised.
struct Polyak<'a> {
    params: &'a mut [f32],
    pairs: &'a [PolyakPair],
    tau: f64,
}

impl VectorKernel for Polyak<'_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        for pair in self.pairs {
            let (online, target) = self.params.split_at_mut(pair.target);
            polyak(&mut target[..pair.len], &online[pair.online..pair.online + pair.len], self.tau);
        }
    }
}
