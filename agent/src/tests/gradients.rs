//! Autograd against central finite differences on tiny f64 networks, for every parameter.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use rand::{SeedableRng, rngs::StdRng};

use super::{f64_policy, normal, tensor, tiny};
use crate::vars::{SeededInit, sorted_vars};
use crate::{
    AgentConfig, QNet, ValueNet, action_prior_log_density, likelihood_ratio_policy_loss, q_loss,
    reparameterized_policy_loss, v_loss,
};

/// Checks d loss / d theta for every element of every variable in `map`.
fn check_gradients(map: &VarMap, loss: impl Fn() -> Tensor) {
    let grads = loss().backward().unwrap();
    // Saturated tanh (1 - tanh^2 ~ 1e-7) makes smaller steps cancel catastrophically.
    let h = 1e-5;
    let mut checked = 0;
    for (name, var) in sorted_vars(map).unwrap() {
        let shape = var.shape().clone();
        let g = grads.get(var.as_tensor()).unwrap_or_else(|| panic!("no gradient for {name}"));
        let g = g.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let values = var.as_tensor().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        for k in 0..values.len() {
            let eval = |delta: f64| {
                let mut v = values.clone();
                v[k] += delta;
                var.set(&Tensor::from_vec(v, shape.clone(), &Device::Cpu).unwrap()).unwrap();
                loss().to_scalar::<f64>().unwrap()
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * h);
            eval(0.0);
            let tol = 1e-5 * (1.0 + fd.abs().max(g[k].abs()));
            assert!((fd - g[k]).abs() < tol, "{name}[{k}]: autograd {} vs finite difference {fd}", g[k]);
            checked += 1;
        }
    }
    assert!(checked > 20, "only {checked} parameters checked");
}

#[test]
fn log_pi_through_the_inverse_pass_has_correct_parameter_gradients() {
    let mut rng = StdRng::seed_from_u64(3);
    for squash in [true, false] {
        let cfg = AgentConfig { squash, ..tiny() };
        let (map, policy) = f64_policy(&cfg, 21);
        let obs = tensor(normal(&mut rng, 3 * 3), 3);
        // y is a constant sample, as in the likelihood-ratio update.
        let y = policy.sample(&obs, &tensor(normal(&mut rng, 3 * 4), 3)).unwrap().pre_squash.detach();
        let w = Tensor::new(&[0.7f64, -1.3, 0.4], &Device::Cpu).unwrap();
        check_gradients(&map, || policy.log_prob(&obs, &y).unwrap().mul(&w).unwrap().sum_all().unwrap());
    }
}

#[test]
fn likelihood_ratio_loss_gradient_is_advantage_weighted_log_pi_gradient() {
    let mut rng = StdRng::seed_from_u64(4);
    let (map, policy) = f64_policy(&tiny(), 2);
    let obs = tensor(normal(&mut rng, 3 * 3), 3);
    let sample = policy.sample(&obs, &tensor(normal(&mut rng, 3 * 4), 3)).unwrap();
    let (y, a) = (sample.pre_squash.detach(), sample.actions.detach());
    let (q, v) = (
        tensor(normal(&mut rng, 3), 1).squeeze(0).unwrap(),
        tensor(normal(&mut rng, 3), 1).squeeze(0).unwrap(),
    );
    let prior = action_prior_log_density(crate::ActionPrior::Normal, &a).unwrap();
    let log_pi = policy.log_prob(&obs, &y).unwrap();
    let loss = likelihood_ratio_policy_loss(&log_pi, &q, &v, &prior, 0.5).unwrap();
    let adv = ((log_pi.detach() - &prior).unwrap().affine(0.5, 0.0).unwrap() - &q).unwrap().add(&v).unwrap();
    let reference = policy.log_prob(&obs, &y).unwrap().mul(&adv).unwrap().mean_all().unwrap();
    let (g1, g2) = (loss.backward().unwrap(), reference.backward().unwrap());
    for (name, var) in sorted_vars(&map).unwrap() {
        let a = g1.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let b = g2.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-12, "{name}: {x} vs {y}");
        }
    }
}

#[test]
fn critic_losses_have_correct_gradients_with_importance_weights() {
    let cfg = tiny();
    let mut rng = StdRng::seed_from_u64(6);
    let init = SeededInit::new(8);
    let (q_map, v_map) = (VarMap::new(), VarMap::new());
    let q = QNet::new(&cfg, init.builder(&q_map, DType::F64, &Device::Cpu)).unwrap();
    let v = ValueNet::new(&cfg, init.builder(&v_map, DType::F64, &Device::Cpu)).unwrap();
    let obs = tensor(normal(&mut rng, 4 * 3), 4);
    let act = tensor(normal(&mut rng, 4 * 4), 4);
    let target = tensor(normal(&mut rng, 4), 1).squeeze(0).unwrap();
    let w = Tensor::new(&[0.2f64, 1.0, 0.5, 0.9], &Device::Cpu).unwrap();
    check_gradients(&q_map, || q_loss(&q.forward(&obs, &act).unwrap(), &target, Some(&w)).unwrap());
    check_gradients(&v_map, || v_loss(&v.forward(&obs).unwrap(), &target).unwrap());
}

#[test]
fn reparameterized_loss_trains_the_policy_through_a_frozen_q() {
    let cfg = tiny();
    let mut rng = StdRng::seed_from_u64(7);
    let (policy_map, policy) = f64_policy(&cfg, 5);
    let q_map = VarMap::new();
    let q = QNet::new(&cfg, SeededInit::new(1).builder(&q_map, DType::F64, &Device::Cpu)).unwrap();
    let obs = tensor(normal(&mut rng, 3 * 3), 3);
    let z = tensor(normal(&mut rng, 3 * 4), 3);
    let loss = || {
        let s = policy.sample(&obs, &z).unwrap();
        let prior = action_prior_log_density(crate::ActionPrior::Normal, &s.actions).unwrap();
        let q_pi = q.forward_frozen(&obs, &s.actions).unwrap();
        reparameterized_policy_loss(&s.log_prob, &q_pi, &prior, 0.3).unwrap()
    };
    check_gradients(&policy_map, loss);
    let grads = loss().backward().unwrap();
    for (name, var) in sorted_vars(&q_map).unwrap() {
        assert!(grads.get(var.as_tensor()).is_none(), "policy loss must not train {name}");
    }
}
