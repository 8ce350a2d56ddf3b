//! [`Learner`]: one SAC-LSP update (`docs/sac-lsp.md` §2-§7) over a [`Batch`], reading top to bottom
//! like the paper.
//!
//! All losses are computed from one forward state with the pre-update parameters; their sum is
//! differentiated once (the losses touch disjoint parameter sets, so each network receives exactly
//! its own loss's gradient), then the Adams step and V-bar is Polyak-averaged towards V. This is
//! what `sac.py`'s single `session.run` of the three train ops does.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

use crate::acting::Actor;
use crate::batch::{Batch, BatchTensors, q_regression};
use crate::config::{AgentConfig, Critic};
use crate::density::action_prior_log_density;
use crate::distributional::{CriticLosses, PolicyTerms, categorical_losses};
use crate::error::{Error, Result};
use crate::losses::{
    likelihood_ratio_policy_loss, q_loss, reparameterized_policy_loss, temperature_loss, v_loss, v_target,
};
use crate::networks::Networks;
use crate::optim::{Adam, AdamConfig};
use crate::params::{Checkpoint, ParamSnapshot, decode, encode, read_i64};
use crate::policy::LatentPolicy;
use crate::target::polyak_update;
use crate::vars::{export, import};

/// Scalar diagnostics of one update, from the pre-update forward pass.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// J_Q of Q1 (IS-weighted if the batch has weights).
    pub q_loss: f32,
    /// J_Q of Q2, with twin Q.
    pub q2_loss: Option<f32>,
    /// J_V.
    pub v_loss: f32,
    /// The policy surrogate loss (its value is not meaningful for the likelihood-ratio form, its
    /// gradient is).
    pub policy_loss: f32,
    /// The temperature loss, when the temperature is learned.
    pub temperature_loss: Option<f32>,
    /// The temperature alpha used by this update.
    pub temperature: f32,
    /// mean log pi(a~|s) of the fresh policy samples (minus the entropy estimate).
    pub mean_log_prob: f32,
    /// mean Q1(s, a) over the batch's actions.
    pub mean_q: f32,
    /// mean V(s).
    pub mean_v: f32,
    /// mean Q target y_q.
    pub mean_q_target: f32,
}

/// What one update returns.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdateOutput {
    /// Scalar diagnostics.
    pub metrics: Metrics,
    /// Signed TD errors delta_i = y_q - Q1(s_i, a_i) with the pre-update parameters, for the
    /// priority update of prioritized replay.
    pub td_errors: Vec<f32>,
}

enum Temperature {
    Fixed(f64),
    Learned { vars: VarMap, log_alpha: Var, adam: Adam },
}

impl std::fmt::Debug for Temperature {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Fixed(a) => f.debug_tuple("Fixed").field(a).finish(),
            Self::Learned { log_alpha, .. } => {
                f.debug_struct("Learned").field("log_alpha", log_alpha).finish()
            }
        }
    }
}

impl Temperature {
    fn alpha(&self) -> Result<f64> {
        Ok(match self {
            Self::Fixed(a) => *a,
            Self::Learned { log_alpha, .. } => f64::from(log_alpha.as_tensor().to_vec1::<f32>()?[0]).exp(),
        })
    }
}

/// Fills `out` (row-major `[rows, act_dim]`) with the latents z ~ N(0, I) of update `step` of a
/// learner seeded with `seed`; shared with the fused learner so both draw the same noise.
pub(crate) fn fill_latent_noise(seed: u64, step: u64, out: &mut [f32]) {
    let mut rng = StdRng::seed_from_u64(run::splitmix64(seed ^ run::splitmix64(step)));
    for z in out {
        *z = rng.sample(StandardNormal);
    }
}

/// Trains one SAC-LSP level: the policy, Q (or twin Q), V, target V-bar, and optionally alpha.
#[derive(Debug)]
pub struct Learner {
    cfg: AgentConfig,
    seed: u64,
    step: u64,
    nets: Networks,
    policy_adam: Adam,
    q_adams: Vec<Adam>,
    v_adam: Adam,
    temperature: Temperature,
}

impl Learner {
    /// Builds and initialises every network from `seed` (`docs/sac-lsp.md` §11). As in `sac.py`, V-bar
    /// is Xavier-initialised on its own and then receives one soft update towards V, not a copy.
    pub fn new(cfg: AgentConfig, seed: u64) -> Result<Self> {
        cfg.validate()?;
        let nets = Networks::new(&cfg, seed, DType::F32)?;
        polyak_update(&nets.v_target.vars, &nets.v.vars, cfg.tau.into())?;
        let adam = AdamConfig::for_agent(&cfg);
        let temperature = if cfg.learn_temperature {
            let vars = VarMap::new();
            let init = candle_nn::Init::Const(f64::from(cfg.initial_temperature).ln());
            vars.get(1, "log_alpha", init, DType::F32, &Device::Cpu)?;
            let log_alpha =
                vars.data().lock().map_err(|_| Error::BadInput("poisoned".into()))?["log_alpha"].clone();
            Temperature::Learned { adam: Adam::new(&vars, adam)?, vars, log_alpha }
        } else {
            Temperature::Fixed(cfg.initial_temperature.into())
        };
        Ok(Self {
            policy_adam: Adam::new(&nets.policy.vars, adam)?,
            q_adams: nets.qs.iter().map(|q| Adam::new(&q.vars, adam)).collect::<Result<_>>()?,
            v_adam: Adam::new(&nets.v.vars, adam)?,
            temperature,
            nets,
            cfg,
            seed,
            step: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// Number of updates done (the version of the next snapshot).
    pub fn step(&self) -> u64 {
        self.step
    }

    /// The policy being trained.
    pub fn policy(&self) -> &LatentPolicy {
        &self.nets.policy.model
    }

    /// The current temperature alpha.
    pub fn temperature(&self) -> Result<f32> {
        Ok(self.temperature.alpha()? as f32)
    }

    /// Latents z ~ N(0, I) for update `step`: a stream per (seed, step), so a restored checkpoint
    /// draws the same noise as the run it came from.
    fn latent_noise(&self, rows: usize) -> Result<Tensor> {
        let mut z = vec![0.0; rows * self.cfg.act_dim];
        fill_latent_noise(self.seed, self.step, &mut z);
        Ok(Tensor::from_vec(z, (rows, self.cfg.act_dim), &Device::Cpu)?)
    }

    /// One simultaneous update of every network from `batch` (`docs/sac-lsp.md` §2-§7), then
    /// V-bar <- (1 - tau) V-bar + tau V.
    pub fn update(&mut self, batch: &Batch) -> Result<UpdateOutput> {
        let cfg = &self.cfg;
        let b = BatchTensors::new(batch, cfg)?;
        let alpha = self.temperature.alpha()?;

        // Q: regress Q(s, a) on y_q = scale r + (1 - d) gamma V-bar(s') (Eq. 2.25), IS-weighted
        // (`docs/sac-lsp.md` §8). With a categorical critic these are the distributions' means,
        // which give the TD errors of the priorities whatever the critic.
        let reg = q_regression(&self.nets, cfg, &b)?;

        // Policy samples a~ and log pi(a~|s) (`docs/sac-lsp.md` §1).
        let policy = &self.nets.policy.model;
        let context = policy.embed(&b.observations)?;
        let z = self.latent_noise(batch.size)?;
        let (log_pi, actions) = if cfg.reparameterize {
            let s = policy.sample_embedded(&context, &z)?;
            (s.log_prob, s.actions)
        } else {
            // Likelihood ratio: y is a constant; log pi is differentiated through the inverse pass.
            let s = policy.sample_embedded(&context.detach(), &z)?;
            (policy.log_prob_embedded(&context, &s.pre_squash.detach())?, s.actions.detach())
        };
        let log_prior = action_prior_log_density(cfg.action_prior, &actions)?;
        let q_pi = self.nets.qs.iter().map(|q| q.model.forward_frozen(&b.observations, &actions));
        let q_pi = q_pi.collect::<candle_core::Result<Vec<_>>>()?;
        let q_pi_min = q_pi.iter().skip(1).try_fold(q_pi[0].clone(), |m, q| m.minimum(q))?;

        let v = self.nets.v.model.forward(&b.observations)?;
        let critic = match cfg.critic {
            // V: regress V(s) on Q(s, a~) - alpha log pi + alpha log p (Eq. 2.23).
            Critic::Scalar => {
                let v_tgt = v_target(&q_pi_min, &log_pi, &log_prior, alpha)?;
                let q_losses = reg
                    .q_values
                    .iter()
                    .map(|q| q_loss(q, &reg.target, b.is_weights.as_ref()))
                    .collect::<candle_core::Result<Vec<_>>>()?;
                let policy_q = if cfg.reparameterize { q_pi_min.clone() } else { q_pi[0].clone() };
                CriticLosses { q_losses, v_loss: v_loss(&v, &v_tgt)?, policy_q, policy_v: v.detach() }
            }
            // A distribution per critic (`docs/sac-lsp.md` §13).
            Critic::Categorical => {
                let terms = PolicyTerms { actions: &actions, log_pi: &log_pi, log_prior: &log_prior, alpha };
                categorical_losses(&self.nets, cfg, batch, &b, &terms, &q_pi[0], &v)?
            }
        };
        let CriticLosses { q_losses, v_loss, policy_q, policy_v } = critic;

        // Policy: likelihood ratio (Eq. 2.27, code's sign, with Q1) or, as an option,
        // reparameterised through min(Q1, Q2) (clipped double Q, as SAC's second version).
        let policy_loss = if cfg.reparameterize {
            reparameterized_policy_loss(&log_pi, &policy_q, &log_prior, alpha)?
        } else {
            likelihood_ratio_policy_loss(&log_pi, &policy_q, &policy_v, &log_prior, alpha)?
        };

        let mut total = (v_loss.clone() + policy_loss.clone())?;
        for l in &q_losses {
            total = (total + l)?;
        }
        let temp_loss = match &self.temperature {
            Temperature::Learned { log_alpha, .. } => {
                let l =
                    temperature_loss(log_alpha.as_tensor(), &log_pi, cfg.effective_target_entropy().into())?;
                total = (total + &l)?;
                Some(l)
            }
            Temperature::Fixed(_) => None,
        };

        let metrics = Metrics {
            q_loss: q_losses[0].to_scalar()?,
            q2_loss: q_losses.get(1).map(|l| l.to_scalar()).transpose()?,
            v_loss: v_loss.to_scalar()?,
            policy_loss: policy_loss.to_scalar()?,
            temperature_loss: temp_loss.map(|l| l.to_scalar()).transpose()?,
            temperature: alpha as f32,
            mean_log_prob: log_pi.mean_all()?.to_scalar()?,
            mean_q: reg.q_values[0].mean_all()?.to_scalar()?,
            mean_v: v.mean_all()?.to_scalar()?,
            mean_q_target: reg.target.mean_all()?.to_scalar()?,
        };
        let td_errors = reg.td_errors.to_vec1()?;

        let grads = total.backward()?;
        for adam in &mut self.q_adams {
            adam.step(&grads)?;
        }
        self.v_adam.step(&grads)?;
        self.policy_adam.step(&grads)?;
        if let Temperature::Learned { adam, .. } = &mut self.temperature {
            adam.step(&grads)?;
        }
        polyak_update(&self.nets.v_target.vars, &self.nets.v.vars, cfg.tau.into())?;
        self.step += 1;
        Ok(UpdateOutput { metrics, td_errors })
    }

    /// Every network's weights, versioned by the learner step.
    pub fn snapshot(&self) -> Result<ParamSnapshot> {
        let mut tensors = Vec::new();
        self.nets.export(&mut tensors)?;
        let safetensors = encode(&tensors, &[("version", self.step.to_string())])?;
        Ok(ParamSnapshot { version: self.step, safetensors })
    }

    /// Overwrites every network's weights (not the optimiser state or step) from a snapshot.
    pub fn load_snapshot(&mut self, snapshot: &ParamSnapshot) -> Result<()> {
        self.nets.import(&snapshot.tensors()?)
    }

    /// An actor with this learner's configuration and current weights.
    pub fn actor(&self, seed: u64) -> Result<Actor> {
        let mut actor = Actor::new(self.cfg.clone(), seed)?;
        actor.load(&self.snapshot()?)?;
        Ok(actor)
    }

    /// The full training state.
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        let mut t = Vec::new();
        self.nets.export(&mut t)?;
        self.policy_adam.export("adam.policy", &mut t)?;
        for (adam, q) in self.q_adams.iter().zip(&self.nets.qs) {
            adam.export(&format!("adam.{}", q.role), &mut t)?;
        }
        self.v_adam.export("adam.v", &mut t)?;
        if let Temperature::Learned { vars, adam, .. } = &self.temperature {
            export("temperature", vars, &mut t)?;
            adam.export("adam.temperature", &mut t)?;
        }
        let dev = &Device::Cpu;
        t.push(("learner.step".into(), Tensor::from_slice(&[self.step as i64], 1, dev)?));
        t.push(("learner.seed".into(), Tensor::from_slice(&[self.seed as i64], 1, dev)?));
        let safetensors = crate::resume::checkpoint_bytes(&t, &self.cfg, self.step)?;
        Ok(Checkpoint { step: self.step, safetensors })
    }

    /// Restores a learner from [`checkpoint`](Self::checkpoint)'s output; `cfg` must describe the
    /// same networks.
    pub fn from_checkpoint(cfg: AgentConfig, checkpoint: &Checkpoint) -> Result<Self> {
        crate::resume::check_resume(&cfg, checkpoint)?;
        let t = decode(&checkpoint.safetensors)?;
        let mut learner = Self::new(cfg, read_i64(&t, "learner.seed")? as u64)?;
        learner.nets.import(&t)?;
        learner.policy_adam.import("adam.policy", &t)?;
        for (adam, q) in learner.q_adams.iter_mut().zip(&learner.nets.qs) {
            adam.import(&format!("adam.{}", q.role), &t)?;
        }
        learner.v_adam.import("adam.v", &t)?;
        if let Temperature::Learned { vars, adam, .. } = &mut learner.temperature {
            import("temperature", vars, &t)?;
            adam.import("adam.temperature", &t)?;
        }
        learner.step = read_i64(&t, "learner.step")? as u64;
        Ok(learner)
    }
}
