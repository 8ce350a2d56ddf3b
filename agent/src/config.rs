//! [`AgentConfig`]: network shapes and hyperparameters, defaulting to the dissertation's baseline.
//!
//! Defaults are the values of `haarnoja/sac` at ca39be1 for the Ant (`examples/variants.py`, 'ant'),
//! the code the dissertation ran; see `docs/sac-lsp.md` §12. The three options beyond the
//! paper (reparameterised gradient, twin Q, learned temperature) are off by default.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The prior p(a) of the action prior term log p(a) in the V target and policy loss
/// (`docs/sac-lsp.md` §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionPrior {
    /// log N(a; 0, I) on the (squashed, if `squash`) action: the paper's Ant setting.
    Normal,
    /// Uniform on the action box: log p(a) = 0.
    Uniform,
}

/// Which critic Q and V are (`docs/sac-lsp.md` §13).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Critic {
    /// A scalar output: the paper's critic.
    #[default]
    Scalar,
    /// A categorical distribution over a fixed support ([`CategoricalConfig`]).
    Categorical,
}

/// Which categorical formulation trains a categorical critic (`docs/sac-lsp.md` §13).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CategoricalVariant {
    /// A distributional soft critic: C51's projection of the soft Bellman target, cross-entropy.
    #[default]
    SoftC51,
    /// The dissertation's formulation as its code ran it (`sac-c51`), kept to reproduce its
    /// negative result: a width-1 layer before the atoms' softmax and a squared loss on a
    /// log-likelihood-like scalar.
    Dissertation,
}

/// The support and formulation of a categorical critic. Defaults: the dissertation's 51 atoms on
/// [-100, 5000] (its §4.3), in scaled-reward units (the units of Q and V), trained as
/// [`CategoricalVariant::SoftC51`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CategoricalConfig {
    /// The formulation. Default `soft_c51`.
    pub variant: CategoricalVariant,
    /// Number of atoms z_i = v_min + i (v_max - v_min) / (atoms - 1). Default 51.
    pub atoms: usize,
    /// The smallest atom. Default -100.
    pub v_min: f32,
    /// The largest atom. Default 5000.
    pub v_max: f32,
}

impl Default for CategoricalConfig {
    fn default() -> Self {
        Self { variant: CategoricalVariant::SoftC51, atoms: 51, v_min: -100.0, v_max: 5000.0 }
    }
}

/// The longest n-step return allowed: past it the uncorrected return is mostly off-policy rewards.
pub const MAX_N_STEP: usize = 20;

/// Configuration of one SAC-LSP level: network shapes and the hyperparameters of its update.
///
/// `obs_dim` and `act_dim` come from the task; everything else defaults to the paper's Ant values.
/// A level trained on top of frozen lower levels is derived with [`AgentConfig::level_above`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AgentConfig {
    /// Observation dimension. Default 105 (Gymnasium Ant-v5; rllab Ant is 125).
    pub obs_dim: usize,
    /// Action dimension of this level (for a higher level: the latent dimension of the level below).
    /// At least 2, since the coupling layers split it in halves. Default 8 (Ant).
    pub act_dim: usize,
    /// Hidden widths of Q(s, a) and V(s), ReLU; the output layer is linear. Default `[128, 128]`.
    pub critic_hidden: Vec<usize>,
    /// Widths of the policy's observation embedding c = E(s), the last one being dim c; hidden
    /// layers are ReLU. Default `[128, 128, 16]` (`preprocessing_hidden_sizes`).
    pub embedding_layers: Vec<usize>,
    /// Whether the embedding's output layer has a ReLU (level 1 of the paper) or is linear
    /// (higher levels, `MLPPreprocessor`'s default). Default true.
    pub embedding_output_relu: bool,
    /// Number of conditional affine coupling layers, alternating odd, even, odd, ... Default 2.
    pub coupling_layers: usize,
    /// Hidden widths (tanh) of each coupling layer's scale and translation nets. Default `[8]`
    /// (`s_t_layers` 1, `s_t_units` 8).
    pub coupling_hidden: Vec<usize>,
    /// Whether actions are squashed a = tanh(y) into [-1, 1]. Default true; false for higher levels,
    /// whose action is the unbounded latent of the level below.
    pub squash: bool,
    /// Prior of the action prior term. Default [`ActionPrior::Normal`].
    pub action_prior: ActionPrior,
    /// Reward scale: rewards are multiplied by it inside the Q target only, which makes the entropy
    /// temperature 1 / scale_reward in reward units. Default 10 (rllab Ant; higher level 3).
    pub scale_reward: f32,
    /// Discount gamma. Default 0.99.
    pub discount: f32,
    /// Polyak rate tau of the target V. Default 0.01.
    pub tau: f32,
    /// Adam learning rate of all networks (at the first update, when it decays). Default 3e-4.
    pub learning_rate: f64,
    /// With `learning_rate_decay_updates`, the learning rate falls linearly to this over that
    /// many updates of each network, and stays. Default none (constant).
    pub final_learning_rate: Option<f64>,
    /// Updates of the linear decay; 0 (default): constant learning rate.
    pub learning_rate_decay_updates: u64,
    /// Adam beta1. Default 0.9 (TensorFlow's default).
    pub adam_beta1: f64,
    /// Adam beta2. Default 0.999 (TensorFlow's default).
    pub adam_beta2: f64,
    /// Adam epsilon, added to sqrt(v) as TensorFlow does (its "epsilon hat"). Default 1e-8.
    pub adam_epsilon: f64,
    /// Transitions per update. Default 128. [`Learner::update`](crate::Learner::update) accepts any
    /// non-empty batch; this is what the learner role samples.
    pub batch_size: usize,
    /// Option beyond the paper: reparameterised policy gradient, L_pi = mean(alpha log pi - Q1 - log p),
    /// instead of the likelihood-ratio estimator. Default false.
    pub reparameterize: bool,
    /// Option beyond the paper: two Q nets (clipped double Q); the V target uses min(Q1, Q2), and so
    /// does the reparameterised policy loss; the likelihood-ratio policy loss and the TD errors use
    /// Q1. Default false.
    pub twin_q: bool,
    /// Option beyond the paper: learn the temperature alpha against a target entropy. alpha multiplies
    /// the entropy and action-prior terms; rewards are still multiplied by `scale_reward`. Default false.
    pub learn_temperature: bool,
    /// Starting (or, when not learned, fixed) temperature alpha. Default 1, i.e. the paper's implicit
    /// temperature 1 / scale_reward in reward units.
    pub initial_temperature: f32,
    /// Target entropy of the learned temperature; `None` means -act_dim. Default `None`.
    pub target_entropy: Option<f32>,
    /// Option beyond the paper: n-step returns (Ape-X). Each stored transition carries the
    /// discounted sum of n rewards and the observation n steps later (built by [`NStepReturns`]
    /// where the env steps are taken), and the Q target bootstraps with discount^n
    /// ([`AgentConfig::bootstrap_discount`]). Default 1, the paper's one-step target.
    ///
    /// [`NStepReturns`]: crate::NStepReturns
    pub n_step: usize,
    /// Option beyond the paper (the dissertation's first extension): the critic's kind. Default
    /// [`Critic::Scalar`]; `categorical` uses the `[agent.categorical]` table.
    pub critic: Critic,
    /// The categorical critic's support and formulation, read when `critic = "categorical"`.
    pub categorical: CategoricalConfig,
}

impl Default for AgentConfig {
    fn default() -> Self {
        Self {
            obs_dim: 105,
            act_dim: 8,
            critic_hidden: vec![128, 128],
            embedding_layers: vec![128, 128, 16],
            embedding_output_relu: true,
            coupling_layers: 2,
            coupling_hidden: vec![8],
            squash: true,
            action_prior: ActionPrior::Normal,
            scale_reward: 10.0,
            discount: 0.99,
            tau: 0.01,
            learning_rate: 3e-4,
            final_learning_rate: None,
            learning_rate_decay_updates: 0,
            adam_beta1: 0.9,
            adam_beta2: 0.999,
            adam_epsilon: 1e-8,
            batch_size: 128,
            reparameterize: false,
            twin_q: false,
            learn_temperature: false,
            initial_temperature: 1.0,
            target_entropy: None,
            n_step: 1,
            critic: Critic::Scalar,
            categorical: CategoricalConfig::default(),
        }
    }
}

impl AgentConfig {
    /// The paper's defaults for a task with these dimensions.
    pub fn for_task(obs_dim: usize, act_dim: usize) -> Self {
        Self { obs_dim, act_dim, ..Self::default() }
    }

    /// The configuration of a level trained on top of this one (`docs/sac-lsp.md` §9): its action is
    /// this level's
    /// latent h (same dimension, unbounded: no squash), with the N(0, I) action prior on h, a linear
    /// embedding output, and the paper's high-level reward scale 3. Other settings are kept.
    pub fn level_above(&self) -> Self {
        Self {
            squash: false,
            action_prior: ActionPrior::Normal,
            embedding_output_relu: false,
            scale_reward: 3.0,
            ..self.clone()
        }
    }

    /// The paper's defaults for level `level` of a hierarchy (0 = the env-facing level): the bottom
    /// level's as [`Default`], every level above as [`level_above`](Self::level_above) of it.
    pub fn default_at_level(level: usize) -> Self {
        if level == 0 { Self::default() } else { Self::default().level_above() }
    }

    /// The networks of a run: its `[agent]` table over the defaults of the trained level (the
    /// level-above ones on top of frozen levels), sized to the run's widths (with HER, the goal is
    /// part of the observation). Not yet validated ([`Self::validate_for_run`]); the error names
    /// the table.
    pub fn from_run(spec: &run::RunSpec) -> std::result::Result<Self, String> {
        let base = Self::default_at_level(spec.hierarchy.depth());
        let dims = spec.dims();
        Ok(Self { obs_dim: dims.obs_dim, act_dim: dims.act_dim, ..spec.table_over("agent", &base)? })
    }

    /// Checks every field, and `[her]` against it (HER needs n_step = 1); the error names the table.
    pub fn validate_for_run(&self, spec: &run::RunSpec) -> std::result::Result<(), String> {
        spec.her.validate(spec.task, self.n_step)?;
        self.validate().map_err(|e| format!("[agent] {e}"))
    }

    /// The discount of the Q target's bootstrap V̄(s'): discount^n_step, since a stored transition
    /// spans n_step env steps.
    pub fn bootstrap_discount(&self) -> f32 {
        self.discount.powi(self.n_step as i32)
    }

    /// Widths of every layer of Q and V after their inputs: the hidden layers, then the output
    /// layers of the critic's kind (one value; the atoms' logits; or the dissertation's width-1
    /// layer and then the atoms' logits).
    pub fn critic_layers(&self) -> Vec<usize> {
        let mut layers = self.critic_hidden.clone();
        match (self.critic, self.categorical.variant) {
            (Critic::Scalar, _) => layers.push(1),
            (Critic::Categorical, CategoricalVariant::SoftC51) => layers.push(self.categorical.atoms),
            (Critic::Categorical, CategoricalVariant::Dissertation) => {
                layers.extend([1, self.categorical.atoms])
            }
        }
        layers
    }

    /// The target entropy actually used by the learned temperature.
    pub fn effective_target_entropy(&self) -> f32 {
        self.target_entropy.unwrap_or(-(self.act_dim as f32))
    }

    /// Checks every field; the error names the first offending one.
    pub fn validate(&self) -> Result<()> {
        let fail = |msg: String| Err(Error::InvalidConfig(msg));
        if self.obs_dim == 0 {
            return fail("obs_dim must be at least 1".into());
        }
        if self.act_dim < 1 {
            return fail(format!("act_dim must be at least 1, got {}", self.act_dim));
        }
        for (name, widths, allow_empty) in [
            ("critic_hidden", &self.critic_hidden, false),
            ("embedding_layers", &self.embedding_layers, false),
            ("coupling_hidden", &self.coupling_hidden, true),
        ] {
            if widths.is_empty() && !allow_empty {
                return fail(format!("{name} must not be empty"));
            }
            if widths.contains(&0) {
                return fail(format!("{name} must not contain a zero width, got {widths:?}"));
            }
        }
        if self.coupling_layers == 0 {
            return fail("coupling_layers must be at least 1".into());
        }
        let positive = |name: &str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                fail(format!("{name} must be finite and > 0, got {x}"))
            }
        };
        positive("scale_reward", self.scale_reward.into())?;
        positive("learning_rate", self.learning_rate)?;
        if let Some(lr) = self.final_learning_rate {
            positive("final_learning_rate", lr)?;
            if self.learning_rate_decay_updates == 0 {
                return fail("final_learning_rate needs learning_rate_decay_updates > 0".into());
            }
        }
        positive("adam_epsilon", self.adam_epsilon)?;
        positive("initial_temperature", self.initial_temperature.into())?;
        if !(0.0..=1.0).contains(&self.discount) {
            return fail(format!("discount must be in [0, 1], got {}", self.discount));
        }
        if !(self.tau > 0.0 && self.tau <= 1.0) {
            return fail(format!("tau must be in (0, 1], got {}", self.tau));
        }
        for (name, beta) in [("adam_beta1", self.adam_beta1), ("adam_beta2", self.adam_beta2)] {
            if !(0.0..1.0).contains(&beta) {
                return fail(format!("{name} must be in [0, 1), got {beta}"));
            }
        }
        if self.batch_size == 0 {
            return fail("batch_size must be at least 1".into());
        }
        if !(1..=MAX_N_STEP).contains(&self.n_step) {
            return fail(format!("n_step must be in [1, {MAX_N_STEP}], got {}", self.n_step));
        }
        if let Some(h) = self.target_entropy
            && !h.is_finite()
        {
            return fail(format!("target_entropy must be finite, got {h}"));
        }
        if self.critic == Critic::Categorical {
            let c = &self.categorical;
            if !(2..=1024).contains(&c.atoms) {
                return fail(format!("categorical.atoms must be in [2, 1024], got {}", c.atoms));
            }
            if !(c.v_min.is_finite() && c.v_max.is_finite() && c.v_min < c.v_max) {
                return fail(format!(
                    "categorical.v_min must be finite and below a finite v_max, got [{}, {}]",
                    c.v_min, c.v_max
                ));
            }
            if self.twin_q {
                // Clipped double Q takes a minimum of two values; of two distributions it is not defined.
                return fail("twin_q is not implemented with a categorical critic".into());
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_papers_ant_values_and_valid() {
        let cfg = AgentConfig::default();
        cfg.validate().unwrap();
        assert_eq!((cfg.obs_dim, cfg.act_dim), (105, 8));
        assert_eq!(cfg.embedding_layers, vec![128, 128, 16]);
        assert_eq!((cfg.scale_reward, cfg.tau, cfg.batch_size), (10.0, 0.01, 128));
        assert!(!cfg.reparameterize && !cfg.twin_q && !cfg.learn_temperature);
        let high = cfg.level_above();
        high.validate().unwrap();
        assert!(!high.squash && !high.embedding_output_relu && high.scale_reward == 3.0);
    }

    #[test]
    fn the_bootstrap_discount_spans_n_steps() {
        let one = AgentConfig::default();
        assert_eq!(one.bootstrap_discount(), 0.99);
        let three = AgentConfig { n_step: 3, ..Default::default() };
        assert!((three.bootstrap_discount() - 0.99f32.powi(3)).abs() < 1e-7);
    }

    fn categorical(categorical: CategoricalConfig, twin_q: bool) -> AgentConfig {
        AgentConfig { critic: Critic::Categorical, categorical, twin_q, ..Default::default() }
    }

    #[test]
    fn critic_layers_end_in_the_heads_outputs() {
        let scalar = AgentConfig::default();
        assert_eq!(scalar.critic_layers(), vec![128, 128, 1]);
        let c51 = categorical(CategoricalConfig::default(), false);
        c51.validate().unwrap();
        assert_eq!(c51.critic_layers(), vec![128, 128, 51]);
        let old = CategoricalConfig { variant: CategoricalVariant::Dissertation, ..Default::default() };
        assert_eq!(categorical(old, false).critic_layers(), vec![128, 128, 1, 51]);
        // A run file's tables read into the same settings.
        let parsed: AgentConfig = toml::from_str(
            "critic = \"categorical\"\n[categorical]\nvariant = \"dissertation\"\natoms = 11\n",
        )
        .unwrap();
        assert_eq!(
            (parsed.critic, parsed.categorical.variant, parsed.categorical.atoms),
            (Critic::Categorical, CategoricalVariant::Dissertation, 11)
        );
    }

    #[test]
    fn validate_names_the_bad_field() {
        let cases: Vec<(AgentConfig, &str)> = vec![
            (AgentConfig { act_dim: 0, ..Default::default() }, "act_dim"),
            (AgentConfig { obs_dim: 0, ..Default::default() }, "obs_dim"),
            (AgentConfig { critic_hidden: vec![], ..Default::default() }, "critic_hidden"),
            (AgentConfig { embedding_layers: vec![4, 0], ..Default::default() }, "embedding_layers"),
            (AgentConfig { coupling_layers: 0, ..Default::default() }, "coupling_layers"),
            (AgentConfig { tau: 0.0, ..Default::default() }, "tau"),
            (AgentConfig { discount: 1.5, ..Default::default() }, "discount"),
            (AgentConfig { scale_reward: f32::NAN, ..Default::default() }, "scale_reward"),
            (AgentConfig { adam_beta2: 1.0, ..Default::default() }, "adam_beta2"),
            (AgentConfig { batch_size: 0, ..Default::default() }, "batch_size"),
            (AgentConfig { n_step: 0, ..Default::default() }, "n_step"),
            (AgentConfig { n_step: 21, ..Default::default() }, "n_step"),
            (categorical(CategoricalConfig { atoms: 1, ..Default::default() }, false), "categorical.atoms"),
            (categorical(CategoricalConfig { v_min: 5.0, v_max: 5.0, ..Default::default() }, false), "v_min"),
            (categorical(CategoricalConfig { v_max: f32::INFINITY, ..Default::default() }, false), "v_min"),
            (categorical(CategoricalConfig::default(), true), "twin_q"),
            (AgentConfig { target_entropy: Some(f32::INFINITY), ..Default::default() }, "target_entropy"),
        ];
        for (cfg, field) in cases {
            let err = cfg.validate().unwrap_err().to_string();
            assert!(err.contains(field), "{err} should name {field}");
        }
    }
}
