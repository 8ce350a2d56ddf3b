//! Behaviour of every task on the real simulator: dimensions, seeded resets, bad actions, clipping,
//! reward terms and time limits.

use sim::{EnvError, Environment, InitState, Task};

fn make(task: Task) -> Box<dyn Environment> {
    sim::make(task, 7).expect("every task builds")
}

#[test]
fn ant_v5_xy_is_ant_v5_with_the_torso_position_in_front() {
    // Gymnasium's exclude_current_positions_from_observation=False: obs = qpos ++ the rest, and the
    // same dynamics, rewards and terminations.
    let (mut plain, mut xy) = (make(Task::AntV5), make(Task::AntV5Xy));
    let (a, b) = (plain.reset(Some(4)), xy.reset(Some(4)));
    assert_eq!(&b[2..], &a[..]);
    for t in 0..50 {
        let action: Vec<f64> = (0..8).map(|i| ((t * 8 + i) as f64 * 0.37).sin()).collect();
        let (s, sx) = (plain.step(&action).unwrap(), xy.step(&action).unwrap());
        assert_eq!(&sx.observation[2..], &s.observation[..], "step {t}");
        assert_eq!((sx.reward, sx.terminated, sx.truncated), (s.reward, s.terminated, s.truncated));
    }
}

#[test]
fn specs_have_the_reference_dimensions() {
    let dims: Vec<_> = Task::ALL
        .iter()
        .map(|t| {
            let s = make(*t).spec().clone();
            (s.name, s.obs_dim, s.act_dim, s.nq, s.nv)
        })
        .collect();
    assert_eq!(
        dims,
        [
            ("ant-v5", 105, 8, 15, 14),
            ("ant-v5-xy", 107, 8, 15, 14),
            ("ant-rllab", 125, 8, 15, 14),
            ("inverted-pendulum", 4, 1, 2, 2)
        ]
    );
    assert!((make(Task::AntV5).spec().dt - 0.05).abs() < 1e-12);
    assert!((make(Task::AntRllab).spec().dt - 0.02).abs() < 1e-12);
}

#[test]
fn task_names_round_trip_and_unknown_names_are_errors() {
    for task in Task::ALL {
        assert_eq!(task.name().parse::<Task>().unwrap(), task);
    }
    assert!("ant-v4".parse::<Task>().is_err());
}

#[test]
fn seeded_resets_are_reproducible_and_seeds_differ() {
    for task in Task::ALL {
        let mut a = make(task);
        let mut b = sim::make(task, 99).unwrap();
        let first = a.reset(Some(3));
        assert_eq!(first, b.reset(Some(3)), "{task}");
        assert_ne!(first, a.reset(Some(4)), "{task}");
        // Unseeded resets continue the stream: two in a row differ, and replay after a reseed.
        a.reset(Some(5));
        let (x, y) = (a.reset(None), a.reset(None));
        assert_ne!(x, y);
        b.reset(Some(5));
        assert_eq!((b.reset(None), b.reset(None)), (x, y), "{task}");
    }
}

#[test]
fn wrong_length_or_non_finite_actions_are_errors_and_the_env_keeps_working() {
    for task in Task::ALL {
        let mut env = make(task);
        env.reset(Some(0));
        let n = env.spec().act_dim;
        assert_eq!(
            env.step(&vec![0.0; n + 1]).unwrap_err(),
            EnvError::ActionDim { expected: n, found: n + 1 }
        );
        let mut bad = vec![0.0; n];
        bad[n - 1] = f64::NAN;
        assert!(matches!(env.step(&bad), Err(EnvError::NonFiniteAction { index, .. }) if index == n - 1));
        bad[n - 1] = f64::INFINITY;
        assert!(env.step(&bad).is_err());
        assert!(env.step(&vec![0.0; n]).is_ok());
    }
}

#[test]
fn ant_v5_clamps_controls_but_charges_the_raw_action() {
    let state = |env: &mut Box<dyn Environment>| env.reset(Some(1));
    let mut a = make(Task::AntV5);
    let mut b = make(Task::AntV5);
    state(&mut a);
    state(&mut b);
    let big = a.step(&[2.0; 8]).unwrap();
    let unit = b.step(&[1.0; 8]).unwrap();
    assert_eq!(big.observation, unit.observation, "MuJoCo clamps ctrl to [-1, 1]");
    let ctrl = 2; // reward_ctrl
    assert_eq!(big.terms.values()[ctrl], -0.5 * 8.0 * 4.0);
    assert_eq!(unit.terms.values()[ctrl], -0.5 * 8.0);
}

#[test]
fn ant_rllab_clips_scaled_actions_and_pays_the_survive_bonus() {
    let mut a = make(Task::AntRllab);
    let mut b = make(Task::AntRllab);
    a.reset(Some(1));
    b.reset(Some(1));
    let big = a.step(&[3.0; 8]).unwrap();
    let unit = b.step(&[1.0; 8]).unwrap();
    assert_eq!(big, unit, "normalize() clips to the action bounds, costs included");
    let terms = unit.terms.values();
    assert_eq!(terms[4], 0.05);
    assert!((terms[1] + terms[2] + terms[3] + terms[4] - unit.reward).abs() < 1e-12);
    assert_eq!(terms[2], -0.005 * 8.0);
}

#[test]
fn ant_v5_reward_is_the_sum_of_its_terms() {
    let mut env = make(Task::AntV5);
    env.reset(Some(2));
    for k in 0..50 {
        let action: Vec<f64> = (0..8).map(|i| ((k * 8 + i) as f64 * 0.37).sin()).collect();
        let step = env.step(&action).unwrap();
        let t = step.terms.values();
        assert!((t[1] + t[2] + t[3] + t[4] - step.reward).abs() < 1e-12);
        assert_eq!(t[4], if step.terminated { 0.0 } else { 1.0 });
    }
}

#[test]
fn episodes_are_truncated_at_the_time_limit() {
    for task in [Task::AntV5, Task::AntRllab] {
        let mut env = make(task);
        env.reset(Some(0));
        let limit = env.spec().max_episode_steps as usize;
        for t in 1..=limit {
            let step = env.step(&[0.0; 8]).unwrap();
            assert_eq!(step.truncated, t == limit, "{task} t={t}");
        }
        env.reset(None);
        assert!(!env.step(&[0.0; 8]).unwrap().truncated, "reset restarts the clock");
    }
}

#[test]
fn a_fallen_pendulum_terminates_with_zero_reward() {
    let mut env = make(Task::InvertedPendulum);
    let tilted = InitState { qpos: vec![0.0, 0.3], qvel: vec![0.0, 0.0] };
    env.reset_to(&tilted).unwrap();
    let step = env.step(&[0.0]).unwrap();
    assert!(step.terminated && step.reward == 0.0);
    let upright = InitState { qpos: vec![0.0, 0.0], qvel: vec![0.0, 0.0] };
    env.reset_to(&upright).unwrap();
    let step = env.step(&[0.0]).unwrap();
    assert!(!step.terminated && step.reward == 1.0);
}

#[test]
fn an_ant_above_the_healthy_range_is_unhealthy() {
    for task in [Task::AntV5, Task::AntRllab] {
        let mut env = make(task);
        let spec = env.spec().clone();
        let mut qpos = vec![0.0; spec.nq];
        qpos[2] = 1.5; // torso far above the healthy range [0.2, 1.0]
        qpos[3] = 1.0;
        env.reset_to(&InitState { qpos, qvel: vec![0.0; spec.nv] }).unwrap();
        assert!(env.step(&[0.0; 8]).unwrap().terminated, "{task}");
    }
}

#[test]
fn initial_states_of_the_wrong_size_or_not_finite_are_errors() {
    let mut env = make(Task::AntV5);
    assert_eq!(
        InitState::from_row(&[0.0; 28], 15, 14).unwrap_err(),
        EnvError::StateDim { expected: 29, found: 28 }
    );
    let mut row = vec![0.0; 29];
    row[4] = f64::NAN;
    assert_eq!(InitState::from_row(&row, 15, 14).unwrap_err(), EnvError::NonFiniteState { index: 4 });
    let short = InitState { qpos: vec![0.0; 14], qvel: vec![0.0; 14] };
    assert!(matches!(env.reset_to(&short), Err(EnvError::StateDim { .. })));
}

#[test]
fn unit_actions_map_onto_the_action_box() {
    let ant = make(Task::AntV5).spec().clone();
    let unit = [0.25f32, -1.0, 1.0, 1e-9, 0.0, 0.5, -0.5, 0.75];
    let expected: Vec<f64> = unit.iter().map(|u| f64::from(*u)).collect();
    assert_eq!(ant.action_from_unit(&unit), expected, "identity on [-1, 1]");
    let pendulum = make(Task::InvertedPendulum).spec().clone();
    assert_eq!(pendulum.action_from_unit(&[1.0]), vec![3.0]);
    assert_eq!(pendulum.action_from_unit(&[-0.5]), vec![-1.5]);
}
