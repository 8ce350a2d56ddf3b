//! The policy's densities against brute force: log pi by change of variables with a numeric
//! Jacobian determinant of the whole map z -> a, the inverse against the forward pass.

use rand::{SeedableRng, rngs::StdRng};

use super::{f64_policy, normal, tensor, tiny};
use crate::{AgentConfig, Parity, standard_normal_log_density};

/// log|det| of a square matrix by Gaussian elimination with partial pivoting.
fn log_abs_det(mut m: Vec<Vec<f64>>) -> f64 {
    let n = m.len();
    let mut acc = 0.0;
    for col in 0..n {
        let pivot = (col..n).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs())).unwrap();
        m.swap(col, pivot);
        let p = m[col][col];
        acc += p.abs().ln();
        let pivot_row = m[col].clone();
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / p;
            for (x, pv) in row.iter_mut().zip(&pivot_row).skip(col) {
                *x -= f * pv;
            }
        }
    }
    acc
}

/// log pi(a|s) = log N(z) - log|det da/dz| with da/dz by central differences.
fn brute_force_log_pi(cfg: &AgentConfig, seed: u64, obs: &[f64], z: &[f64]) -> f64 {
    let (_, policy) = f64_policy(cfg, seed);
    let obs = tensor(obs.to_vec(), 1);
    let map = |z: &[f64]| -> Vec<f64> {
        policy.deterministic(&obs, &tensor(z.to_vec(), 1)).unwrap().flatten_all().unwrap().to_vec1().unwrap()
    };
    let d = z.len();
    let h = 1e-5;
    let mut jac = vec![vec![0.0; d]; d];
    for j in 0..d {
        let (mut up, mut down) = (z.to_vec(), z.to_vec());
        up[j] += h;
        down[j] -= h;
        let (a_up, a_down) = (map(&up), map(&down));
        for i in 0..d {
            jac[i][j] = (a_up[i] - a_down[i]) / (2.0 * h);
        }
    }
    let log_n = standard_normal_log_density(&tensor(z.to_vec(), 1)).unwrap().to_vec1::<f64>().unwrap()[0];
    log_n - log_abs_det(jac)
}

#[test]
fn log_pi_through_inverse_matches_brute_force_change_of_variables() {
    let mut rng = StdRng::seed_from_u64(11);
    for (squash, layers) in [(false, 2), (false, 3), (true, 2), (true, 3)] {
        let cfg = AgentConfig { squash, coupling_layers: layers, ..tiny() };
        let mut cases = 0;
        for seed in 0..40 {
            let obs = normal(&mut rng, 3);
            let z: Vec<f64> = normal(&mut rng, 4).iter().map(|v| 0.5 * v).collect();
            let (_, policy) = f64_policy(&cfg, seed);
            let obs_t = tensor(obs.clone(), 1);
            let sample = policy.sample(&obs_t, &tensor(z.clone(), 1)).unwrap();
            let y = sample.pre_squash.flatten_all().unwrap().to_vec1::<f64>().unwrap();
            // Saturated tanh defeats the numeric Jacobian; such draws say nothing here.
            if squash && y.iter().any(|v| v.abs() > 2.5) {
                continue;
            }
            let via_inverse =
                policy.log_prob(&obs_t, &sample.pre_squash).unwrap().to_vec1::<f64>().unwrap()[0];
            let via_forward = sample.log_prob.to_vec1::<f64>().unwrap()[0];
            // The code's squash term is log(1 - tanh^2 + eps); the exact Jacobian has no eps.
            let eps_shift: f64 = if squash {
                y.iter().map(|v| (1.0 - v.tanh().powi(2) + 1e-6).ln() - (1.0 - v.tanh().powi(2)).ln()).sum()
            } else {
                0.0
            };
            let brute = brute_force_log_pi(&cfg, seed, &obs, &z);
            assert!(
                (via_inverse + eps_shift - brute).abs() < 1e-6,
                "squash {squash}: {via_inverse} vs brute {brute}"
            );
            assert!((via_inverse - via_forward).abs() < 1e-10, "{via_inverse} vs {via_forward}");
            cases += 1;
        }
        assert!(cases >= 5, "only {cases} unsaturated cases");
    }
}

#[test]
fn inverse_undoes_forward_and_negates_its_log_det() {
    let mut rng = StdRng::seed_from_u64(5);
    let (_, policy) = f64_policy(&AgentConfig { coupling_layers: 3, ..tiny() }, 9);
    let obs = tensor(normal(&mut rng, 5 * 3), 5);
    let z = tensor(normal(&mut rng, 5 * 4), 5);
    let c = policy.embed(&obs).unwrap();
    let fwd = policy.bijector_forward(&z, &c).unwrap();
    let inv = policy.bijector_inverse(&fwd.output, &c).unwrap();
    let err = (inv.output - &z).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap();
    assert!(err < 1e-12, "round trip error {err}");
    let ld =
        (fwd.log_det + inv.log_det).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap();
    assert!(ld < 1e-12);
    // The map is not the identity: the test would be vacuous otherwise.
    let moved = (fwd.output - &z).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap();
    assert!(moved > 1e-2);
}

#[test]
fn odd_layer_keeps_second_half_even_layer_keeps_first_half() {
    use crate::{Coupling, CouplingSpec, Grad};
    let mut rng = StdRng::seed_from_u64(2);
    let x = tensor(normal(&mut rng, 2 * 4), 2);
    let c = tensor(normal(&mut rng, 2 * 3), 2);
    for (parity, kept) in [(Parity::Odd, 2..4), (Parity::Even, 0..2)] {
        let map = candle_nn::VarMap::new();
        let vb =
            crate::vars::SeededInit::new(1).builder(&map, candle_core::DType::F64, &candle_core::Device::Cpu);
        let spec = CouplingSpec { parity, dim: 4, context_dim: 3, hidden: &[3] };
        let y = Coupling::new(&spec, vb).unwrap().forward(&x, &c, Grad::Track).unwrap().output;
        let (xv, yv) = (x.to_vec2::<f64>().unwrap(), y.to_vec2::<f64>().unwrap());
        for (xr, yr) in xv.iter().zip(&yv) {
            for j in 0..4 {
                assert_eq!(kept.contains(&j), xr[j] == yr[j], "{parity:?} column {j}");
            }
        }
    }
    assert_eq!(
        (Parity::of_layer(0), Parity::of_layer(1), Parity::of_layer(2)),
        (Parity::Odd, Parity::Even, Parity::Odd)
    );
}

#[test]
fn deterministic_mode_is_the_forward_map_of_the_given_latent() {
    let (_, policy) = f64_policy(&tiny(), 4);
    let mut rng = StdRng::seed_from_u64(8);
    let obs = tensor(normal(&mut rng, 2 * 3), 2);
    let h = tensor(normal(&mut rng, 2 * 4), 2);
    let a = policy.deterministic(&obs, &h).unwrap();
    let s = policy.sample(&obs, &h).unwrap();
    assert_eq!(a.to_vec2::<f64>().unwrap(), s.actions.to_vec2::<f64>().unwrap());
    assert_eq!(s.actions.to_vec2::<f64>().unwrap(), s.pre_squash.tanh().unwrap().to_vec2::<f64>().unwrap());
}

#[test]
fn a_one_dimensional_action_gets_a_conditional_affine_policy_with_exact_log_pi() {
    let mut rng = StdRng::seed_from_u64(3);
    let cfg = AgentConfig { act_dim: 1, ..tiny() };
    let mut cases = 0;
    for seed in 0..20 {
        let obs = normal(&mut rng, 3);
        let z = vec![0.5 * normal(&mut rng, 1)[0]];
        let (_, policy) = f64_policy(&cfg, seed);
        let obs_t = tensor(obs.clone(), 1);
        let sample = policy.sample(&obs_t, &tensor(z.clone(), 1)).unwrap();
        let y = sample.pre_squash.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        if y[0].abs() > 2.5 {
            continue;
        }
        let via_inverse = policy.log_prob(&obs_t, &sample.pre_squash).unwrap().to_vec1::<f64>().unwrap()[0];
        let eps_shift = (1.0 - y[0].tanh().powi(2) + 1e-6).ln() - (1.0 - y[0].tanh().powi(2)).ln();
        let brute = brute_force_log_pi(&cfg, seed, &obs, &z);
        assert!((via_inverse + eps_shift - brute).abs() < 1e-6, "{via_inverse} vs brute {brute}");
        // The even layer really moves the one component (the odd one is the identity).
        assert!((y[0] - z[0]).abs() > 1e-6);
        cases += 1;
    }
    assert!(cases >= 5, "only {cases} unsaturated cases");
}
