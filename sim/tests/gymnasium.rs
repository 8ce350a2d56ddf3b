//! Replays trajectories recorded from Gymnasium 1.4.0 + MuJoCo 3.17.0 (tests/reference/make_fixture.py)
//! and checks every observation, reward, reward term and flag against them bit for bit.
//!
//! The fixtures are exact: make_fixture.py writes the initial state, the actions (float64) and every
//! recorded value (float64, as Gymnasium returns them) with Python's `repr`, the shortest decimal that
//! reads back as the same double, and Rust's `f64` parsing rounds correctly, so each value here is
//! Gymnasium's own double. The simulation is the MuJoCo 3.17.0 library Gymnasium ran (deploy/setup.sh
//! takes it from the mujoco==3.17.0 wheel), and the rewards repeat numpy's summation order (sim's
//! `numpy` module), so nothing may differ: not by an ulp, not in the sign of a zero (the Ant's
//! fixture holds `-0.0`s).

use std::path::Path;

use sim::{InitState, Task};

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines.next().expect("a header row").split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse::<f64>().expect("a number")).collect()).collect();
    (header, rows)
}

fn replay(task: Task, fixture: &str) {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let (_, actions) = read_csv(&data.join(format!("{fixture}.actions.csv")));
    let (header, expected) = read_csv(&data.join(format!("{fixture}.expected.csv")));
    // The init file has no header: read_csv took its only row as the header.
    let init: Vec<f64> = std::fs::read_to_string(data.join(format!("{fixture}.init.csv")))
        .expect("the init fixture")
        .trim()
        .split(',')
        .map(|v| v.parse().expect("a number"))
        .collect();
    assert!(!init.is_empty() && actions.len() + 1 == expected.len());

    let mut env = sim::make(task, 0).expect("the task builds");
    let spec = env.spec().clone();
    assert_eq!(header.len(), 1 + spec.obs_dim + 3 + spec.reward_terms.len());
    for (name, column) in spec.reward_terms.iter().zip(&header[1 + spec.obs_dim + 3..]) {
        assert_eq!(name, column);
    }
    let first =
        env.reset_to(&InitState::from_row(&init, spec.nq, spec.nv).expect("a valid state")).expect("reset");
    // Every value that differs, as "t=.. column: got .., gymnasium ..", to report them all at once.
    let (mut differ, mut values) = (Vec::new(), 0);
    let mut check = |t: usize, got: &[f64], want: &[f64]| {
        assert_eq!(got.len(), want.len(), "t={t}: the row's length");
        values += got.len();
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            if g.to_bits() != w.to_bits() {
                differ.push(format!("t={t} {}: got {g:?}, gymnasium {w:?}", header[1 + i]));
            }
        }
    };
    // Row 0 is the reset: its observation, then zeros where a step's reward, flags and terms go.
    check(0, &first, &expected[0][1..1 + spec.obs_dim]);
    let mut terminations = 0;
    for (t, action) in actions.iter().enumerate() {
        let step = env.step(action).expect("a valid action");
        let mut row = step.observation.clone();
        row.extend([step.reward, f64::from(u8::from(step.terminated)), f64::from(u8::from(step.truncated))]);
        row.extend_from_slice(step.terms.values());
        check(t + 1, &row, &expected[t + 1][1..]);
        terminations += usize::from(step.terminated);
    }
    assert!(
        differ.is_empty(),
        "{fixture}: {} of {values} values differ from gymnasium's:\n{}",
        differ.len(),
        differ.iter().take(20).cloned().collect::<Vec<_>>().join("\n")
    );
    assert!(terminations > 0, "the fixture should exercise terminations");
    eprintln!(
        "{fixture}: {} steps, all {values} values bit for bit, {terminations} terminated steps",
        actions.len()
    );
}

#[test]
fn ant_v5_matches_gymnasium() {
    replay(Task::AntV5, "ant_v5");
}

#[test]
fn inverted_pendulum_matches_gymnasium() {
    replay(Task::InvertedPendulum, "inverted_pendulum");
}
