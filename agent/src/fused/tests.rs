//! The fused learner against the candle learner: gradients, per-row log pi, N updates (metrics,
//! TD errors, parameters), checkpoints and snapshots across backends, and the dispatch.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

use super::layout::Role;
use super::{AnyLearner, Backend, FusedLearner};
use crate::batch::{BatchTensors, q_regression};
use crate::learning::fill_latent_noise;
use crate::networks::Networks;
use crate::params::decode;
use crate::vars::sorted_vars;
use crate::{
    ActionPrior, Actor, AgentConfig, Batch, Learner, Metrics, Mode, action_prior_log_density,
    likelihood_ratio_policy_loss, q_loss, v_loss, v_target,
};

/// obs 3, act 4, critics 6-5-1, embedding 5-3, s/t nets 7 -> 3 tanh -> 2.
fn tiny() -> AgentConfig {
    AgentConfig {
        critic_hidden: vec![6, 5],
        embedding_layers: vec![5, 3],
        coupling_hidden: vec![3],
        learning_rate: 1e-3,
        ..AgentConfig::for_task(3, 4)
    }
}

/// Shape variations of the paper's configuration: a hierarchy level (no squash, linear embedding
/// output, scale 3) with three coupling layers, an odd action dimension, the uniform prior,
/// alpha != 1, linear s/t nets, a one-layer embedding, a 1-d action (odd coupling = identity).
fn variants() -> Vec<AgentConfig> {
    vec![
        tiny(),
        AgentConfig { coupling_layers: 3, act_dim: 5, ..tiny().level_above() },
        AgentConfig {
            action_prior: ActionPrior::Uniform,
            initial_temperature: 0.7,
            coupling_hidden: vec![],
            embedding_layers: vec![4, 6, 3],
            ..tiny()
        },
        AgentConfig { embedding_layers: vec![4], ..tiny() },
        AgentConfig { act_dim: 1, coupling_layers: 3, ..tiny() },
    ]
}

/// The options beyond the paper, alone and together, on the shapes above: the reparameterised
/// gradient (squashed, unsquashed with three couplings, 1-d), twin Q, the learned temperature,
/// all three with the uniform prior (the ant-v5 default), and 3-step returns (bootstrap discount^3).
fn option_variants() -> Vec<AgentConfig> {
    let all = |cfg: AgentConfig| AgentConfig {
        reparameterize: true,
        twin_q: true,
        learn_temperature: true,
        action_prior: ActionPrior::Uniform,
        ..cfg
    };
    vec![
        AgentConfig { reparameterize: true, ..tiny() },
        AgentConfig { reparameterize: true, coupling_layers: 3, act_dim: 5, ..tiny().level_above() },
        AgentConfig { twin_q: true, ..tiny() },
        AgentConfig {
            learn_temperature: true,
            initial_temperature: 0.3,
            target_entropy: Some(-1.5),
            ..tiny()
        },
        all(tiny()),
        all(AgentConfig { embedding_layers: vec![4], initial_temperature: 0.5, ..tiny() }),
        all(AgentConfig { act_dim: 1, ..tiny() }),
        all(AgentConfig { n_step: 3, ..tiny() }),
        all(AgentConfig { final_learning_rate: Some(1e-4), learning_rate_decay_updates: 6, ..tiny() }),
    ]
}

fn batch(cfg: &AgentConfig, size: usize, seed: u64, weighted: bool) -> Batch {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut draw = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    Batch {
        size,
        observations: draw(size * cfg.obs_dim),
        actions: draw(size * cfg.act_dim).iter().map(|a| a.tanh()).collect(),
        rewards: draw(size),
        next_observations: draw(size * cfg.obs_dim),
        terminated: (0..size).map(|i| if i % 5 == 2 { 1.0 } else { 0.0 }).collect(),
        is_weights: weighted.then(|| draw(size).iter().map(|w| 0.5 + w.abs()).collect()),
    }
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-3)
}

fn assert_metrics_close(fused: &Metrics, candle: &Metrics, rel: f32) {
    let pairs = [
        ("q_loss", fused.q_loss, candle.q_loss),
        ("v_loss", fused.v_loss, candle.v_loss),
        ("policy_loss", fused.policy_loss, candle.policy_loss),
        ("mean_log_prob", fused.mean_log_prob, candle.mean_log_prob),
        ("mean_q", fused.mean_q, candle.mean_q),
        ("mean_v", fused.mean_v, candle.mean_v),
        ("mean_q_target", fused.mean_q_target, candle.mean_q_target),
        ("temperature", fused.temperature, candle.temperature),
    ];
    for (name, f, c) in pairs {
        assert!(close(f, c, rel), "{name}: fused {f} vs candle {c}");
    }
    for (name, f, c) in [
        ("q2_loss", fused.q2_loss, candle.q2_loss),
        ("temperature_loss", fused.temperature_loss, candle.temperature_loss),
    ] {
        match (f, c) {
            (Some(f), Some(c)) => assert!(close(f, c, rel), "{name}: fused {f} vs candle {c}"),
            (None, None) => {}
            _ => panic!("{name}: fused {f:?} vs candle {c:?}"),
        }
    }
}

/// Largest |a - b| / max(1, |a|, |b|) (absolute for parameters, relative for Adam's second moments,
/// which grow with g^2) over every tensor of two snapshots or checkpoints, and where it is.
fn max_param_diff(a: &HashMap<String, Tensor>, b: &HashMap<String, Tensor>) -> (f32, String) {
    assert_eq!(a.len(), b.len());
    let mut worst = (0.0f32, String::new());
    for (name, t) in a {
        let flat =
            |t: &Tensor| t.to_dtype(DType::F32).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let (x, y) = (flat(t), flat(&b[name]));
        for (x, y) in x.iter().zip(&y) {
            let d = (x - y).abs() / x.abs().max(y.abs()).max(1.0);
            if d > worst.0 {
                worst = (d, name.clone());
            }
        }
    }
    worst
}

/// The candle learner's loss graph (`Learner::update`, likelihood-ratio path) on networks loaded
/// from `fused`, differentiated by candle: every parameter's gradient by `{role}.{name}`, and
/// the per-row (y, log pi).
fn candle_gradients(fused: &FusedLearner, b: &Batch) -> (HashMap<String, Vec<f32>>, Vec<f32>, Vec<f32>) {
    let cfg = &fused.cfg;
    let nets = Networks::new(cfg, 0, DType::F32).unwrap();
    nets.import(&fused.snapshot().unwrap().tensors().unwrap()).unwrap();
    let bt = BatchTensors::new(b, cfg).unwrap();
    let alpha = f64::from(cfg.initial_temperature);
    let reg = q_regression(&nets, cfg, &bt).unwrap();
    let q_loss = q_loss(&reg.q_values[0], &reg.target, bt.is_weights.as_ref()).unwrap();
    let policy = &nets.policy.model;
    let context = policy.embed(&bt.observations).unwrap();
    let mut z = vec![0.0; b.size * cfg.act_dim];
    fill_latent_noise(fused.seed, fused.step, &mut z);
    let z = Tensor::from_vec(z, (b.size, cfg.act_dim), &Device::Cpu).unwrap();
    let sample = policy.sample_embedded(&context.detach(), &z).unwrap();
    let log_pi = policy.log_prob_embedded(&context, &sample.pre_squash.detach()).unwrap();
    let actions = sample.actions.detach();
    let log_prior = action_prior_log_density(cfg.action_prior, &actions).unwrap();
    let q_pi = nets.qs[0].model.forward_frozen(&bt.observations, &actions).unwrap();
    let v = nets.v.model.forward(&bt.observations).unwrap();
    let v_loss = v_loss(&v, &v_target(&q_pi, &log_pi, &log_prior, alpha).unwrap()).unwrap();
    let policy_loss = likelihood_ratio_policy_loss(&log_pi, &q_pi, &v.detach(), &log_prior, alpha).unwrap();
    let grads = ((v_loss + policy_loss).unwrap() + q_loss).unwrap().backward().unwrap();
    let mut out = HashMap::new();
    for (role, vars) in [("policy", &nets.policy.vars), ("q1", &nets.qs[0].vars), ("v", &nets.v.vars)] {
        for (name, var) in sorted_vars(vars).unwrap() {
            let g = grads.get(var.as_tensor()).unwrap_or_else(|| panic!("no gradient for {role}.{name}"));
            out.insert(format!("{role}.{name}"), g.flatten_all().unwrap().to_vec1::<f32>().unwrap());
        }
    }
    let y = sample.pre_squash.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    (out, y, log_pi.to_vec1::<f32>().unwrap())
}

#[test]
fn gradients_and_inverse_pass_log_pi_match_candle_autograd() {
    // Exact tanh: only summation order inside some GEMMs may differ. Fast tanh: <= 1.3 ulp per
    // tanh, a few ulp after the nets.
    for (exact, tol) in [(true, 2e-6), (false, 2e-5)] {
        for (k, cfg) in variants().into_iter().enumerate() {
            let mut fused = FusedLearner::new(cfg.clone(), 10 + k as u64).unwrap().with_exact_tanh(exact);
            let b = batch(&cfg, 9, k as u64, k != 1);
            let (want, y, log_pi) = candle_gradients(&fused, &b);
            fused.compute_gradients(&b);
            let flow = &fused.work.flow;
            for (i, (f, c)) in flow.y.iter().zip(&y).enumerate() {
                assert!(close(*f, *c, tol), "config {k}: y[{i}] fused {f} vs candle {c}");
            }
            for (i, (f, c)) in flow.log_pi.iter().zip(&log_pi).enumerate() {
                assert!(close(*f, *c, tol), "config {k}: log pi[{i}] fused {f} vs candle {c}");
            }
            let mut checked = 0;
            for a in fused.layout.arrays.iter().filter(|a| a.role != Role::VTarget) {
                let key = format!("{}.{}", a.role.name(), a.name);
                let (got, want) = (&fused.grads[a.offset..a.offset + a.len], &want[&key]);
                // Relative to the array's largest gradient, since single elements can cancel.
                let scale = want.iter().fold(1e-6f32, |m, g| m.max(g.abs()));
                for (j, (g, w)) in got.iter().zip(want).enumerate() {
                    assert!((g - w).abs() <= tol * scale, "config {k}: d{key}[{j}] fused {g} vs candle {w}");
                }
                checked += 1;
            }
            assert_eq!(checked, want.len(), "config {k}: every trained array has a gradient");
        }
    }
}

/// How far apart two learners may end: parameters (absolute), and whole checkpoints (networks,
/// V-bar, Adam's moments and step counts; see [`max_param_diff`]).
#[derive(Clone, Copy, Debug)]
struct Tolerance {
    params: f32,
    checkpoint: f32,
}

/// Exact tanh: bit-identical (the one non-zero case is summation order in one GEMM, 5e-10).
const EXACT: Tolerance = Tolerance { params: 1e-8, checkpoint: 1e-6 };
/// Fast tanh: parameters within 1e-6 in practice; Adam's first moments, averages of gradients
/// that cancel over the batch, keep the relative differences of the gradients (~1e-5, up to
/// 1.7e-4 with a one-layer embedding, whose four ReLU features feed the couplings directly; with
/// exact tanh that configuration is bit-identical, so the difference is the tanh's rounding).
const FAST: Tolerance = Tolerance { params: 1e-5, checkpoint: 5e-4 };

/// The options beyond the paper sum their gradients in other orders than candle's graph does
/// (the reparameterised path through the flow, the Qs' input gradients), so even with exact tanh
/// they agree to rounding, not bit for bit; Adam's normalised steps keep that at ~1e-6 of the
/// parameters.
const OPTIONS: Tolerance = Tolerance { params: 2e-5, checkpoint: 2e-4 };

/// N updates of both learners from one state: metrics, TD errors, parameters and checkpoints.
fn run_side_by_side(cfg: AgentConfig, batches: &[Batch], updates: usize, exact: bool) {
    let paper = !(cfg.reparameterize || cfg.twin_q || cfg.learn_temperature);
    let tol = match (paper, exact) {
        (true, true) => EXACT,
        (true, false) => FAST,
        (false, _) => OPTIONS,
    };
    let metrics_rel = if paper { 1e-5 } else { 1e-4 };
    let mut candle = Learner::new(cfg.clone(), 5).unwrap();
    let mut fused = FusedLearner::from_learner(&candle).unwrap().with_exact_tanh(exact);
    for step in 0..updates {
        let b = &batches[step % batches.len()];
        let (c, f) = (candle.update(b).unwrap(), fused.update(b).unwrap());
        assert_metrics_close(&f.metrics, &c.metrics, metrics_rel);
        for (i, (x, y)) in f.td_errors.iter().zip(&c.td_errors).enumerate() {
            assert!(close(*x, *y, metrics_rel), "update {step}: td[{i}] fused {x} vs candle {y}");
        }
    }
    let (fs, cs) = (fused.snapshot().unwrap(), candle.snapshot().unwrap());
    let (diff, name) = max_param_diff(&fs.tensors().unwrap(), &cs.tensors().unwrap());
    assert!(
        diff <= tol.params,
        "exact tanh {exact}, {updates} updates: parameters differ by {diff} in {name}"
    );
    let (fc, cc) = (fused.checkpoint().unwrap(), candle.checkpoint().unwrap());
    assert_eq!(fc.step, cc.step);
    let (diff, name) = max_param_diff(&decode(&fc.safetensors).unwrap(), &decode(&cc.safetensors).unwrap());
    assert!(
        diff <= tol.checkpoint,
        "exact tanh {exact}, {updates} updates: checkpoints differ by {diff} in {name}"
    );
}

#[test]
fn updates_match_candle_on_small_networks() {
    for (k, cfg) in variants().into_iter().enumerate() {
        let batches: Vec<Batch> = (0..3).map(|s| batch(&cfg, 7 + s, 20 + s as u64, k == 0)).collect();
        run_side_by_side(cfg.clone(), &batches, 15, true);
        run_side_by_side(cfg, &batches, 15, false);
    }
}

#[test]
fn updates_match_candle_for_every_option() {
    for (k, cfg) in option_variants().into_iter().enumerate() {
        let batches: Vec<Batch> = (0..3).map(|s| batch(&cfg, 7 + s, 40 + s as u64, k % 2 == 0)).collect();
        run_side_by_side(cfg.clone(), &batches, 15, true);
        run_side_by_side(cfg, &batches, 15, false);
    }
}

#[test]
fn updates_match_candle_at_ant_sizes() {
    let cfg = AgentConfig::for_task(105, 8);
    let batches = [batch(&cfg, 128, 1, true), batch(&cfg, 128, 2, false)];
    run_side_by_side(cfg.clone(), &batches, 3, true);
    run_side_by_side(cfg.clone(), &batches, 3, false);
    let options = AgentConfig {
        reparameterize: true,
        twin_q: true,
        learn_temperature: true,
        action_prior: ActionPrior::Uniform,
        scale_reward: 1.0,
        ..cfg
    };
    run_side_by_side(options.clone(), &batches, 3, true);
    run_side_by_side(options, &batches, 3, false);
}

#[test]
fn checkpoints_and_snapshots_cross_backends() {
    let cfg = tiny();
    let b = batch(&cfg, 6, 3, false);
    // Same seed: byte-identical initial checkpoints.
    let fused = FusedLearner::new(cfg.clone(), 4).unwrap();
    let same = fused.checkpoint().unwrap() == Learner::new(cfg.clone(), 4).unwrap().checkpoint().unwrap();
    assert!(same, "initial checkpoints differ");
    // Train fused, resume in candle and fused: identical next updates, up to rounding.
    let mut fused = fused;
    for _ in 0..3 {
        fused.update(&b).unwrap();
    }
    let checkpoint = fused.checkpoint().unwrap();
    let mut candle = Learner::from_checkpoint(cfg.clone(), &checkpoint).unwrap();
    let mut resumed = FusedLearner::from_checkpoint(cfg.clone(), &checkpoint).unwrap();
    assert_eq!((candle.step(), resumed.step()), (3, 3));
    let (f, r, c) = (fused.update(&b).unwrap(), resumed.update(&b).unwrap(), candle.update(&b).unwrap());
    assert_eq!(f, r);
    assert_metrics_close(&f.metrics, &c.metrics, 1e-5);
    assert_eq!(candle.checkpoint().unwrap().step, fused.checkpoint().unwrap().step);
    // A fused snapshot drives the candle actor exactly like the same weights loaded into candle.
    let snap = fused.snapshot().unwrap();
    let mut via_candle = Learner::new(cfg.clone(), 99).unwrap();
    via_candle.load_snapshot(&snap).unwrap();
    let (diff, name) =
        max_param_diff(&via_candle.snapshot().unwrap().tensors().unwrap(), &snap.tensors().unwrap());
    assert_eq!(diff, 0.0, "{name}");
    let (mut a1, mut a2) = (fused.actor(8).unwrap(), Actor::new(cfg.clone(), 8).unwrap());
    a2.load(&via_candle.snapshot().unwrap()).unwrap();
    let obs = &b.observations[..cfg.obs_dim];
    assert_eq!(a1.act(obs, Mode::Explore).unwrap(), a2.act(obs, Mode::Explore).unwrap());
    // And a candle snapshot loads into the fused learner; a mismatched one is refused.
    let mut other = FusedLearner::new(cfg.clone(), 1).unwrap();
    other.load_snapshot(&snap).unwrap();
    let (diff, name) =
        max_param_diff(&other.snapshot().unwrap().tensors().unwrap(), &snap.tensors().unwrap());
    assert_eq!(diff, 0.0, "{name}");
    let wrong = Learner::new(AgentConfig { critic_hidden: vec![4, 5], ..cfg }, 1).unwrap();
    assert!(other.load_snapshot(&wrong.snapshot().unwrap()).is_err());
}

#[test]
fn batch_size_changes_reallocate_and_bad_batches_are_refused() {
    let cfg = tiny();
    let mut candle = Learner::new(cfg.clone(), 2).unwrap();
    let mut fused = FusedLearner::from_learner(&candle).unwrap();
    for size in [4, 11, 4] {
        let b = batch(&cfg, size, size as u64, true);
        let (c, f) = (candle.update(&b).unwrap(), fused.update(&b).unwrap());
        assert_eq!(f.td_errors.len(), size);
        assert_metrics_close(&f.metrics, &c.metrics, 1e-5);
    }
    let bad = Batch { rewards: vec![0.0; 2], ..batch(&cfg, 4, 1, false) };
    assert!(fused.update(&bad).unwrap_err().to_string().contains("batch.rewards"));
}

#[test]
fn dispatch_runs_every_option_fused_and_names_what_it_cannot() {
    let paper = AgentConfig::default();
    assert!(FusedLearner::supports(&paper) && FusedLearner::supports(&paper.level_above()));
    for cfg in variants().into_iter().chain(option_variants()) {
        assert_eq!(Backend::Auto.resolve(&cfg).unwrap(), Backend::Fused, "{cfg:?}");
    }
    // A policy with no coupling layer that moves anything: candle only, and said so.
    let identity = AgentConfig { act_dim: 1, coupling_layers: 1, ..tiny() };
    assert_eq!(Backend::Auto.resolve(&identity).unwrap(), Backend::Candle);
    let err = AnyLearner::new(identity, 1, Backend::Fused).unwrap_err().to_string();
    assert!(err.contains("coupling"), "{err}");
    let cfg = tiny();
    let b = batch(&cfg, 5, 9, false);
    let mut auto = AnyLearner::new(cfg.clone(), 3, Backend::Auto).unwrap();
    let mut candle = AnyLearner::new(cfg.clone(), 3, Backend::Candle).unwrap();
    assert_eq!((auto.backend(), candle.backend()), (Backend::Fused, Backend::Candle));
    let (f, c) = (auto.update(&b).unwrap(), candle.update(&b).unwrap());
    assert_metrics_close(&f.metrics, &c.metrics, 1e-5);
    assert_eq!((auto.step(), auto.temperature().unwrap(), auto.config()), (1, 1.0, &cfg));
    let resumed = AnyLearner::from_checkpoint(cfg, &candle.checkpoint().unwrap(), Backend::Fused).unwrap();
    assert_eq!(resumed.step(), 1);
    // A learned temperature moves, and a fused checkpoint carries it (and its Adam) to candle.
    let learned = AgentConfig { learn_temperature: true, reparameterize: true, twin_q: true, ..tiny() };
    let mut fused = FusedLearner::new(learned.clone(), 2).unwrap();
    for _ in 0..3 {
        fused.update(&b).unwrap();
    }
    assert_ne!(fused.temperature(), 1.0);
    let back = Learner::from_checkpoint(learned, &fused.checkpoint().unwrap()).unwrap();
    assert_eq!(back.temperature().unwrap(), fused.temperature());
}

#[test]
fn a_checkpoint_names_what_it_holds_and_refuses_a_changed_setting() {
    let cfg = tiny();
    let checkpoint = FusedLearner::new(cfg.clone(), 4).unwrap().checkpoint().unwrap();
    let metadata = crate::checkpoint_metadata(&checkpoint.safetensors).unwrap();
    assert_eq!(metadata[crate::CONTAINS_KEY], crate::CONTAINS);
    assert_eq!(metadata["setting.critic_hidden"], "[6, 5]");
    // Tunable settings may change on resume, on either backend.
    let retuned = AgentConfig { learning_rate: 5e-4, batch_size: 7, discount: 0.9, ..cfg.clone() };
    assert!(Learner::from_checkpoint(retuned.clone(), &checkpoint).is_ok());
    assert!(FusedLearner::from_checkpoint(retuned, &checkpoint).is_ok());
    // Shapes, the critic and which state exists may not; the error names the setting. (One Q
    // network fewer would otherwise resume silently, dropping the second Q's weights and moments.)
    let changed = [
        ("twin_q", AgentConfig { twin_q: !cfg.twin_q, ..cfg.clone() }),
        ("critic_hidden", AgentConfig { critic_hidden: vec![6], ..cfg.clone() }),
        ("learn_temperature", AgentConfig { learn_temperature: !cfg.learn_temperature, ..cfg.clone() }),
        ("obs_dim", AgentConfig { obs_dim: 4, ..cfg.clone() }),
    ];
    for (setting, other) in changed {
        let error = Learner::from_checkpoint(other.clone(), &checkpoint).unwrap_err().to_string();
        assert!(error.contains(&format!("[agent] {setting} = ")), "{setting}: {error}");
        if FusedLearner::check_support(&other).is_ok() {
            let error = FusedLearner::from_checkpoint(other, &checkpoint).unwrap_err().to_string();
            assert!(error.contains(setting), "{setting}: {error}");
        }
    }
}
