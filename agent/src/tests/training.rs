//! Learner and actor end to end: losses fall on a fixed batch, IS weights, TD errors agree between
//! learner and actor, snapshots and checkpoints round-trip.

use super::{random_batch, small};
use crate::{
    Actor, AgentConfig, Batch, CategoricalConfig, CategoricalVariant, Critic, Learner, Metrics, Mode,
};

fn mean(xs: &[f32]) -> f32 {
    xs.iter().sum::<f32>() / xs.len() as f32
}

fn train(cfg: AgentConfig, batch: &Batch, updates: usize) -> (Learner, Vec<Metrics>) {
    let mut learner = Learner::new(cfg, 1).unwrap();
    let metrics = (0..updates).map(|_| learner.update(batch).unwrap().metrics).collect();
    (learner, metrics)
}

fn assert_losses_fall(metrics: &[Metrics]) {
    // First 5 updates against the last 20: V's target moves as Q grows, so V's loss is not monotone.
    let window = |f: fn(&Metrics) -> f32, from: usize, n: usize| {
        mean(&metrics[from..from + n].iter().map(f).collect::<Vec<_>>())
    };
    let last = metrics.len() - 20;
    let (q0, q1) = (window(|m| m.q_loss, 0, 5), window(|m| m.q_loss, last, 20));
    let (v0, v1) = (window(|m| m.v_loss, 0, 5), window(|m| m.v_loss, last, 20));
    assert!(q1 < 0.5 * q0, "Q loss {q0} -> {q1}");
    assert!(v1 < 0.5 * v0, "V loss {v0} -> {v1}");
    assert!(metrics.iter().all(|m| m.policy_loss.is_finite() && m.mean_log_prob.is_finite()));
}

#[test]
fn paper_update_lowers_q_and_v_losses_on_a_fixed_batch() {
    let cfg = small();
    let batch = random_batch(&cfg, 64, 3);
    let (learner, metrics) = train(cfg, &batch, 300);
    assert_losses_fall(&metrics);
    assert_eq!(learner.step(), 300);
    assert!(
        metrics.iter().all(|m| m.q2_loss.is_none() && m.temperature_loss.is_none() && m.temperature == 1.0)
    );
}

#[test]
fn options_reparameterize_twin_q_learned_temperature_also_train() {
    let cfg = AgentConfig { reparameterize: true, twin_q: true, learn_temperature: true, ..small() };
    let batch = random_batch(&cfg, 64, 4);
    let (learner, metrics) = train(cfg, &batch, 300);
    assert_losses_fall(&metrics);
    assert!(metrics.iter().all(|m| m.q2_loss.is_some() && m.temperature_loss.is_some()));
    assert!(learner.temperature().unwrap() != 1.0);
}

#[test]
fn importance_weights_scale_the_q_loss_only() {
    let cfg = small();
    let batch = random_batch(&cfg, 16, 5);
    let ones = Batch { is_weights: Some(vec![1.0; 16]), ..batch.clone() };
    let twos = Batch { is_weights: Some(vec![2.0; 16]), ..batch.clone() };
    let plain = Learner::new(cfg.clone(), 2).unwrap().update(&batch).unwrap();
    let with_ones = Learner::new(cfg.clone(), 2).unwrap().update(&ones).unwrap();
    let with_twos = Learner::new(cfg, 2).unwrap().update(&twos).unwrap();
    assert_eq!(plain, with_ones);
    assert!((with_twos.metrics.q_loss - 2.0 * plain.metrics.q_loss).abs() < 1e-5 * plain.metrics.q_loss);
    assert_eq!(
        (with_twos.metrics.v_loss, with_twos.metrics.policy_loss),
        (plain.metrics.v_loss, plain.metrics.policy_loss)
    );
    assert_eq!(with_twos.td_errors, plain.td_errors);
}

#[test]
fn td_errors_are_pre_update_and_match_the_actor() {
    let cfg = small();
    let batch = random_batch(&cfg, 8, 6);
    let mut learner = Learner::new(cfg.clone(), 3).unwrap();
    learner.update(&batch).unwrap();
    let mut actor = Actor::new(cfg.clone(), 9).unwrap();
    actor.load(&learner.snapshot().unwrap()).unwrap();
    assert_eq!(actor.version(), Some(1));
    let from_actor = actor.td_errors(&batch).unwrap();
    let out = learner.update(&batch).unwrap();
    assert_eq!(from_actor, out.td_errors);
    // delta = y_q - Q(s, a): its mean is mean_q_target - mean_q.
    let implied = out.metrics.mean_q_target - out.metrics.mean_q;
    assert!((mean(&out.td_errors) - implied).abs() < 1e-4);
}

#[test]
fn snapshot_round_trip_gives_identical_outputs() {
    let cfg = AgentConfig { twin_q: true, ..small() };
    let batch = random_batch(&cfg, 8, 7);
    let (trained, _) = train(cfg.clone(), &batch, 5);
    let snap = trained.snapshot().unwrap();
    assert_eq!(snap.version, 5);
    let names: Vec<String> = {
        let mut n: Vec<String> = snap.tensors().unwrap().into_keys().collect();
        n.sort();
        n
    };
    for expected in [
        "policy.coupling1.translation.layer1.bias",
        "q1.layer0.weight_action",
        "q2.layer2.weight",
        "v_target.layer0.bias",
    ] {
        assert!(names.iter().any(|n| n == expected), "{expected} not in {names:?}");
    }
    let mut other = Learner::new(cfg.clone(), 99).unwrap();
    other.load_snapshot(&snap).unwrap();
    assert_eq!(other.snapshot().unwrap().tensors().unwrap().len(), names.len());
    let (mut a, mut b) = (Actor::new(cfg.clone(), 4).unwrap(), Actor::new(cfg.clone(), 4).unwrap());
    a.load(&snap).unwrap();
    b.load(&Learner::snapshot(&other).unwrap()).unwrap();
    let obs = &batch.observations[..cfg.obs_dim];
    for mode in [Mode::Explore, Mode::Deterministic, Mode::Explore] {
        assert_eq!(a.act(obs, mode).unwrap(), b.act(obs, mode).unwrap());
    }
    assert_eq!(a.td_errors(&batch).unwrap(), b.td_errors(&batch).unwrap());
    // A mismatched network refuses the snapshot instead of loading part of it.
    let mut wrong = Actor::new(AgentConfig { critic_hidden: vec![8], ..cfg }, 1).unwrap();
    assert!(wrong.load(&snap).is_err());
}

#[test]
fn checkpoint_resumes_bit_identically() {
    for cfg in
        [small(), AgentConfig { twin_q: true, learn_temperature: true, reparameterize: true, ..small() }]
    {
        let batch = random_batch(&cfg, 16, 8);
        let (mut original, _) = train(cfg.clone(), &batch, 3);
        let checkpoint = original.checkpoint().unwrap();
        assert_eq!(checkpoint.step, 3);
        let mut restored = Learner::from_checkpoint(cfg.clone(), &checkpoint).unwrap();
        assert_eq!(restored.step(), 3);
        for _ in 0..2 {
            assert_eq!(original.update(&batch).unwrap(), restored.update(&batch).unwrap());
        }
        assert_eq!(original.checkpoint().unwrap(), restored.checkpoint().unwrap());
    }
}

#[test]
fn actor_modes_and_input_checks() {
    let cfg = small();
    let mut actor = Actor::new(cfg.clone(), 5).unwrap();
    let obs = vec![0.3; cfg.obs_dim];
    let d1 = actor.act(&obs, Mode::Deterministic).unwrap();
    assert_eq!(d1, actor.act(&obs, Mode::Deterministic).unwrap());
    assert_eq!(d1.action, d1.env_action);
    assert_ne!(actor.act(&obs, Mode::Explore).unwrap(), actor.act(&obs, Mode::Explore).unwrap());
    actor.redraw_fixed_latent();
    assert_ne!(d1, actor.act(&obs, Mode::Deterministic).unwrap());
    assert!(actor.act(&obs[1..], Mode::Explore).is_err());
    let bad = Batch { rewards: vec![0.0; 3], ..random_batch(&cfg, 4, 1) };
    assert!(actor.td_errors(&bad).unwrap_err().to_string().contains("batch.rewards"));
}

fn categorical(variant: CategoricalVariant) -> AgentConfig {
    let categorical = CategoricalConfig { variant, atoms: 21, v_min: -60.0, v_max: 200.0 };
    AgentConfig { critic: Critic::Categorical, categorical, ..small() }
}

#[test]
fn soft_c51_fits_its_targets_and_its_td_errors_are_the_actors() {
    let cfg = categorical(CategoricalVariant::SoftC51);
    let batch = random_batch(&cfg, 64, 9);
    let mut learner = Learner::new(cfg.clone(), 1).unwrap();
    let outs: Vec<_> = (0..300).map(|_| learner.update(&batch).unwrap()).collect();
    // The TD errors are the distributions' means against the mean target: they shrink as the
    // cross-entropies fall.
    let abs_td = |o: &crate::UpdateOutput| mean(&o.td_errors.iter().map(|d| d.abs()).collect::<Vec<_>>());
    let first = mean(&outs[..5].iter().map(abs_td).collect::<Vec<_>>());
    let last = mean(&outs[280..].iter().map(abs_td).collect::<Vec<_>>());
    assert!(last < 0.5 * first, "mean |TD| {first} -> {last}");
    let (q0, q1) = (outs[0].metrics.q_loss, outs[299].metrics.q_loss);
    assert!(q1 < q0, "cross-entropy {q0} -> {q1}");
    assert!(outs.iter().all(|o| o.metrics.policy_loss.is_finite() && o.metrics.v_loss.is_finite()));
    let mut actor = Actor::new(cfg, 2).unwrap();
    actor.load(&learner.snapshot().unwrap()).unwrap();
    assert_eq!(actor.td_errors(&batch).unwrap(), learner.update(&batch).unwrap().td_errors);
}

#[test]
fn the_dissertations_categorical_critic_trains_without_non_finite_values() {
    let cfg = categorical(CategoricalVariant::Dissertation);
    let batch = Batch { is_weights: Some(vec![0.5; 16]), ..random_batch(&cfg, 16, 10) };
    let (mut learner, metrics) = train(cfg.clone(), &batch, 30);
    assert!(
        metrics.iter().all(|m| [m.q_loss, m.v_loss, m.policy_loss, m.mean_q].iter().all(|x| x.is_finite()))
    );
    // Resume and snapshot work as for the scalar critic.
    let mut restored = Learner::from_checkpoint(cfg, &learner.checkpoint().unwrap()).unwrap();
    assert_eq!(learner.update(&batch).unwrap(), restored.update(&batch).unwrap());
}

#[test]
fn a_categorical_critic_runs_on_candle_under_auto_and_is_refused_by_fused() {
    use crate::{AnyLearner, Backend};
    let cfg = categorical(CategoricalVariant::SoftC51);
    assert_eq!(AnyLearner::new(cfg.clone(), 1, Backend::Auto).unwrap().backend(), Backend::Candle);
    let err = AnyLearner::new(cfg, 1, Backend::Fused).unwrap_err().to_string();
    assert!(err.contains("categorical"), "{err}");
}
