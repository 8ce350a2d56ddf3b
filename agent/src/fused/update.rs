//! The fused update: [`Learner::update`](crate::Learner::update)'s maths (`docs/sac-lsp.md` §2-§7) on the
//! arena, with every intermediate in a [`Workspace`] allocated once per batch size.
//!
//! Order of work (all from the pre-update parameters, as `sac.py`'s single `session.run`):
//! 1. one GEMM s [W_V0; W_E0; W_Q0,obs (; W_Q2,obs)]^T for the first layers that read s;
//! 2. V-bar(s') -> y_q; V(s); the embedding c = E(s);
//! 3. y = f(z; c), a~ = tanh(y); each Q on [a; a~] as one 2B-row batch (shared observation
//!    product);
//! 4. log pi: likelihood ratio, by the inverse pass z = f^-1(y; c) (y fixed); reparameterised, by
//!    the sampling pass's own change of variables (z fixed);
//! 5. losses and output gradients (`objective.rs`);
//! 6. backward: reparameterised, first dL/da~ through the Qs on the a~ rows with their
//!    pre-update weights (no Q parameter gradient: Q is frozen in the policy loss); then each Q
//!    on the B batch rows, V, the bijector (back through the inverse or the sampling pass) then
//!    the embedding, and one GEMM for every first-layer weight gradient; no input gradients of
//!    first layers;
//! 7. Adam, array by array as each gradient becomes final during step 6 (`adam.rs`'s
//!    [`Trainable`](super::adam::Trainable)); log alpha's, when learned; then
//!    V-bar <- (1 - tau) V-bar + tau V.

use crate::batch::Batch;
use crate::config::AgentConfig;
use crate::learning::{UpdateOutput, fill_latent_noise};

use super::FusedLearner;
use super::adam::{AdamStep, Trainable, polyak};
use super::dense::Activation::{self, Linear, Relu};
use super::dense::{
    MlpBufs, Net, backward_to_first, bias, bias_act_from, forward, forward_rest, input_gradient, sum_bias_act,
};
use super::flow::{self, Flow, FlowBufs, SampleGrads};
use super::layout::{Layout, MlpAt, PolyakPair, QAt, Role};
use super::linalg::{Mat, MatMut, VectorKernel, vectorized};
use super::objective::{LossScalars, Objective, RowGrads, RowInputs, objective};

/// Every intermediate of one update for `rows` transitions.
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    rows: usize,
    /// s [W_V0; W_E0; W_Q0,obs]^T, `rows x obs.rows`.
    obs_pre: Vec<f32>,
    /// The first layers' pre-activation gradients, same layout.
    obs_grad: Vec<f32>,
    v_target: MlpBufs,
    v: MlpBufs,
    /// Each Q on 2 rows per transition: (s, a) in the top half, (s, a~) in the bottom half.
    qs: Vec<MlpBufs>,
    /// [a; a~], `2 rows x act_dim`.
    q_actions: Vec<f32>,
    embedding: MlpBufs,
    pub(super) flow: FlowBufs,
    z: Vec<f32>,
    log_pi_grad: Vec<f32>,
    /// dL_pi/da~ of the reparameterised loss (through the Qs and the action prior), `rows x act_dim`.
    action_grad: Vec<f32>,
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
            qs: layout.qs.iter().map(|q| MlpBufs::new(&q.mlp.widths(), 2 * rows, true)).collect(),
            q_actions: vec![0.0; 2 * rows * cfg.act_dim],
            embedding: MlpBufs::new(&layout.embedding.widths(), rows, true),
            flow: FlowBufs::new(&layout.couplings, rows, cfg.act_dim, context),
            z: vec![0.0; rows * cfg.act_dim],
            log_pi_grad: vec![0.0; rows],
            action_grad: vec![0.0; rows * cfg.act_dim],
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
    embedding: Net<'a>,
}

/// A critic: ReLU hidden layers, linear output.
fn critic(at: &MlpAt) -> Net<'_> {
    Net { at, hidden: Relu, output: Linear }
}

fn nets<'a>(lay: &'a Layout, cfg: &AgentConfig) -> Nets<'a> {
    Nets {
        v_target: critic(&lay.v_target),
        v: critic(&lay.v),
        embedding: Net { at: &lay.embedding, hidden: Relu, output: embedding_output(cfg) },
    }
}

/// Q's `layer0.weight_action` as an `[H_q, act_dim]` view.
fn action_weight<'a>(p: &'a [f32], q: &QAt, act_dim: usize) -> Mat<'a> {
    let h = q.mlp.layers[0].out;
    Mat::dense(&p[q.action_weight..q.action_weight + h * act_dim], h, act_dim)
}

impl FusedLearner {
    /// Steps 1-4: every forward value the losses need, into the workspace.
    fn forward_pass(&mut self, batch: &Batch) {
        let (cfg, lay, gemm, p) = (&self.cfg, &self.layout, &self.gemm, &self.params);
        let Nets { v_target, v, embedding } = nets(lay, cfg);
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
        bias_act_from(&mut w.embedding.act_mut(0, b), e_pre, bias(p, first), embedding.act(0));
        forward_rest(gemm, p, embedding, &mut w.embedding, b);

        fill_latent_noise(self.seed, self.step, &mut w.z[..b * d]);
        let c = w.embedding.output(b);
        flow::sample(gemm, p, flow, &mut w.flow, &w.z, c, cfg.reparameterize);
        w.q_actions[..b * d].copy_from_slice(&batch.actions);
        // libm's tanh, as candle, for the squash whatever the nets use (see `tanh.rs`).
        let a = &mut w.q_actions[b * d..2 * b * d];
        for (a, y) in a.iter_mut().zip(&w.flow.y) {
            *a = if cfg.squash { y.tanh() } else { *y };
        }

        // Q's first layer: per-input products summed, then the bias (mlp.rs's Dense order); the
        // observation product is shared by both halves.
        for (q, bufs) in lay.qs.iter().zip(&mut w.qs) {
            let first = &q.mlp.layers[0];
            let h = first.out;
            let actions = Mat::dense(&w.q_actions, 2 * b, d);
            gemm.mul(&mut bufs.act_mut(0, 2 * b), actions, action_weight(p, q, d).t(), false);
            let (top, bottom) = bufs.acts[0].split_at_mut(b * h);
            let obs_part = pre.columns(q.obs, h);
            sum_bias_act(&mut MatMut::dense(top, b, h), obs_part, bias(p, first), Relu);
            sum_bias_act(&mut MatMut::dense(&mut bottom[..b * h], b, h), obs_part, bias(p, first), Relu);
            forward_rest(gemm, p, critic(&q.mlp), bufs, 2 * b);
        }

        let squashed = cfg.squash.then(|| &w.q_actions[b * d..2 * b * d]);
        if cfg.reparameterize {
            flow::sample_log_pi(&mut w.flow, &w.z, b, squashed);
        } else {
            flow::inverse(gemm, p, flow, &mut w.flow, c, squashed, true);
        }
    }

    /// dL_pi/da~ of the reparameterised loss into `work.action_grad`: back through each Q on the
    /// a~ rows from the gradients [`objective`] left there (Q's weights held fixed), plus the
    /// action prior's term dL/dlog p * dlog p/da~ (N(0, I): dlog p/da~ = -a~).
    fn reparameterized_action_grad(&mut self, b: usize, log_prior_grad: f32) {
        let (cfg, lay, gemm, p, w) = (&self.cfg, &self.layout, &self.gemm, &self.params, &mut self.work);
        let d = cfg.act_dim;
        let mut da = MatMut::dense(&mut w.action_grad[..b * d], b, d);
        for (k, (q, bufs)) in lay.qs.iter().zip(&mut w.qs).enumerate() {
            let weight = action_weight(p, q, d);
            input_gradient(gemm, p, critic(&q.mlp), bufs, b..2 * b, weight, (&mut da, k > 0));
        }
        if cfg.action_prior == crate::config::ActionPrior::Normal {
            let a = &w.q_actions[b * d..2 * b * d];
            for (g, a) in w.action_grad[..b * d].iter_mut().zip(a) {
                // candle: sqr().sum(1).affine(-0.5, c) backward is (g * -0.5) * a * 2.
                *g += ((log_prior_grad * -0.5) * a) * 2.0;
            }
        }
    }

    /// Steps 6-7: every trained gradient into `self.grads`; with `step`, Adam on each array as soon
    /// as its gradient is final, then the Polyak average of V-bar.
    fn backward_pass(&mut self, batch: &Batch, objective: &Objective, step: bool) {
        let b = batch.size;
        if self.cfg.reparameterize {
            self.reparameterized_action_grad(b, objective.log_prior_grad);
        }
        // This update's Adam scalars per parameter set (their step counts advance at the end).
        let steps = step.then(|| self.adam_steps.map(|t| AdamStep::new(&self.adam, t + 1)));
        let step_of = |role: Role| Some(steps?[role.adam_index()?]);
        let (cfg, lay, gemm, w) = (&self.cfg, &self.layout, &self.gemm, &mut self.work);
        let Nets { v, embedding, .. } = nets(lay, cfg);
        let flow = Flow { couplings: &lay.couplings, tanh: self.tanh };
        let mut train = Trainable::new(&mut self.params, &mut self.grads, &mut self.adam_m, &mut self.adam_v);
        let (o, d, width) = (cfg.obs_dim, cfg.act_dim, lay.obs.rows);

        for (q, bufs) in lay.qs.iter().zip(&mut w.qs) {
            train.set_step(step_of(q.role));
            let h = q.mlp.layers[0].out;
            let first = Some(block(&mut w.obs_grad, b, width, q.obs, h));
            backward_to_first(gemm, &mut train, critic(&q.mlp), bufs, b, first);
            let g0 = Mat::dense(&w.obs_grad, b, width).columns(q.obs, h);
            let mut dw = train.grad_matrix(q.action_weight, h, d);
            gemm.mul(&mut dw, g0.t(), Mat::dense(&batch.actions, b, d), false);
            train.finished(q.action_weight, h * d);
        }

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
        if cfg.reparameterize {
            let grads = SampleGrads {
                action: &w.action_grad[..b * d],
                squashed: cfg.squash.then(|| &w.q_actions[b * d..2 * b * d]),
                log_pi: &w.log_pi_grad[..b],
            };
            flow::backward_sample(gemm, &mut train, flow, &mut w.flow, grads, &mut dc);
        } else {
            flow::backward(gemm, &mut train, flow, &mut w.flow, &w.log_pi_grad[..b], &mut dc);
        }
        let h = lay.embedding.layers[0].out;
        let first = Some(block(&mut w.obs_grad, b, width, lay.obs.embedding, h));
        backward_to_first(gemm, &mut train, embedding, &mut w.embedding, b, first);

        // The stacked first layer: one weight-gradient GEMM, then each network's part.
        let s = Mat::dense(&batch.observations, b, o);
        let mut dw = train.grad_matrix(lay.obs.weight, width, o);
        gemm.mul(&mut dw, Mat::dense(&w.obs_grad, b, width).t(), s, false);
        let firsts = [(Role::V, &lay.v.layers[0]), (Role::Policy, &lay.embedding.layers[0])];
        let q_firsts = lay.qs.iter().map(|q| (q.role, &q.mlp.layers[0]));
        for (role, layer) in firsts.into_iter().chain(q_firsts) {
            train.set_step(step_of(role));
            train.finished(layer.weight, layer.out * o);
        }

        if let (Some(at), Some(grad)) = (lay.log_alpha, objective.log_alpha_grad) {
            train.set_step(step_of(Role::Temperature));
            train.grad_matrix(at, 1, 1).row_mut(0)[0] = grad;
            train.finished(at, 1);
        }

        if step {
            vectorized(Polyak { params: train.params_mut(), pairs: &lay.polyak, tau: cfg.tau.into() });
            for (role, t) in Role::TRAINED.iter().zip(&mut self.adam_steps) {
                if lay.has(*role) {
                    *t += 1;
                }
            }
        }
    }

    /// One update from `batch` (validated by the caller), returning the metrics and TD errors.
    pub(super) fn update_validated(&mut self, batch: &Batch) -> UpdateOutput {
        let (out, objective) = self.losses(batch);
        self.backward_pass(batch, &objective, true);
        self.step += 1;
        out
    }

    /// Steps 1-6: the losses, TD errors and every gradient (into `self.grads`), no parameter change.
    #[cfg(test)]
    pub(super) fn compute_gradients(&mut self, batch: &Batch) -> UpdateOutput {
        let (out, objective) = self.losses(batch);
        self.backward_pass(batch, &objective, false);
        out
    }

    /// Steps 1-5: forward pass, losses, TD errors and the output gradients.
    fn losses(&mut self, batch: &Batch) -> (UpdateOutput, Objective) {
        let b = batch.size;
        if self.work.rows() != b {
            self.work = Workspace::new(&self.cfg, &self.layout, b);
        }
        self.forward_pass(batch);
        let cfg = &self.cfg;
        let log_alpha = self.layout.log_alpha.map(|at| self.params[at]);
        let scalars = LossScalars {
            scale_reward: cfg.scale_reward,
            discount: cfg.bootstrap_discount(),
            alpha: log_alpha.map_or(cfg.initial_temperature.into(), |l| f64::from(l).exp()),
            normal_prior: cfg.action_prior == crate::config::ActionPrior::Normal,
            reparameterize: cfg.reparameterize,
            temperature: log_alpha.map(|l| (l, cfg.effective_target_entropy())),
        };
        let w = &mut self.work;
        let mut td_errors = vec![0.0; b];
        // The critics end in one unit, so their last buffers are plain per-row columns.
        let (q_outs, mut q_grads): (Vec<&[f32]>, Vec<&mut [f32]>) =
            w.qs.iter_mut()
                .map(|q| {
                    let last = q.acts.len() - 1;
                    (&q.acts[last][..2 * b], &mut q.grads[last][..2 * b])
                })
                .unzip();
        let last_v = w.v.acts.len() - 1;
        let objective = objective(
            scalars,
            RowInputs {
                rewards: &batch.rewards,
                terminated: &batch.terminated,
                is_weights: batch.is_weights.as_deref(),
                next_value: &w.v_target.acts[w.v_target.acts.len() - 1][..b],
                qs: &q_outs,
                v: &w.v.acts[last_v][..b],
                log_pi: &w.flow.log_pi[..b],
                actions_pi: Mat::dense(&w.q_actions[b * cfg.act_dim..], b, cfg.act_dim),
            },
            RowGrads {
                qs: &mut q_grads,
                v: &mut w.v.grads[last_v][..b],
                log_pi: &mut w.log_pi_grad[..b],
                td_errors: &mut td_errors,
            },
        );
        (UpdateOutput { metrics: objective.metrics.clone(), td_errors }, objective)
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
