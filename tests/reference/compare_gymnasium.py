#!/usr/bin/env python3
"""Compare `sac-lsp rollout` with Gymnasium value for value.

For each trial: reset Gymnasium's env with a seed, take that state (qpos, qvel) as the initial state,
draw random actions, step Gymnasium through them, run `sac-lsp rollout --init-state` with the same
files, and report the largest absolute difference in observations, rewards, reward terms and the
termination flags. Exits non-zero when anything differs by more than --tol.

Needs `pip install gymnasium[mujoco]==1.4.0 mujoco==3.17.0`.
Usage: tests/reference/compare_gymnasium.py --bin target/release/sac-lsp [--task ant-v5] [--trials 5]
"""
import argparse, csv, pathlib, subprocess, sys, tempfile

import gymnasium as gym
import numpy as np

GYM_IDS = {"ant-v5": "Ant-v5", "inverted-pendulum": "InvertedPendulum-v5"}
TERMS = {"ant-v5": ["x_velocity", "reward_forward", "reward_ctrl", "reward_contact", "reward_survive"],
         "inverted-pendulum": ["reward_survive"]}


def gymnasium_rollout(task, seed, actions):
    env = gym.make(GYM_IDS[task])
    obs, _ = env.reset(seed=seed)
    u = env.unwrapped
    init = np.concatenate([u.data.qpos, u.data.qvel])
    rows = [np.concatenate([[0], obs, [0, 0, 0], np.zeros(len(TERMS[task]))])]
    for t, a in enumerate(actions):
        obs, r, term, trunc, info = env.step(a)
        rows.append(np.concatenate([[t + 1], obs, [r, term, trunc], [info[k] for k in TERMS[task]]]))
    return init, np.array(rows)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", required=True)
    p.add_argument("--task", default="ant-v5", choices=sorted(GYM_IDS))
    p.add_argument("--trials", type=int, default=5)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    p.add_argument("--tol", type=float, default=1e-6)
    args = p.parse_args()
    rng = np.random.default_rng(12345)
    worst = 0.0
    for trial in range(args.trials):
        env = gym.make(GYM_IDS[args.task])
        low, high = env.action_space.low, env.action_space.high
        actions = rng.uniform(low, high, size=(args.steps, len(low))).astype(args.dtype)
        init, expected = gymnasium_rollout(args.task, trial, actions)
        with tempfile.TemporaryDirectory() as d:
            d = pathlib.Path(d)
            np.savetxt(d / "actions.csv", actions, delimiter=",", fmt="%.17g",
                       header=",".join(f"a{i}" for i in range(len(low))), comments="")
            np.savetxt(d / "init.csv", init[None, :], delimiter=",", fmt="%.17g")
            cmd = [args.bin, "rollout", "--task", args.task, "--actions", str(d / "actions.csv"),
                   "--init-state", str(d / "init.csv"), "--out", str(d / "out.csv"),
                   "--action-dtype", "f64" if args.dtype == "float64" else "f32"]
            subprocess.run(cmd, check=True)
            with open(d / "out.csv") as f:
                header = next(csv.reader(f))
            got = np.loadtxt(d / "out.csv", delimiter=",", skiprows=1)
        if got.shape != expected.shape:
            sys.exit(f"trial {trial}: shape {got.shape} != gymnasium {expected.shape}")
        diff = np.abs(got - expected)
        col = int(diff.max(axis=0).argmax())
        row = int(diff[:, col].argmax())
        terminations = int(expected[:, header.index("terminated")].sum())
        print(f"trial {trial}: max |diff| {diff.max():.3e} (column {header[col]}, t={row}); "
              f"gymnasium terminations {terminations}")
        worst = max(worst, float(diff.max()))
    print(f"worst max |diff| over {args.trials} trials x {args.steps} steps: {worst:.3e} (tol {args.tol})")
    sys.exit(0 if worst <= args.tol else 1)


if __name__ == "__main__":
    main()
