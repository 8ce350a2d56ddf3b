#!/usr/bin/env python3
"""Write a Gymnasium reference trajectory that sim's tests replay (sim/tests/data/).

Output: <name>.init.csv (qpos then qvel after a seeded Gymnasium reset), <name>.actions.csv (random
actions as float64, printed exactly) and <name>.expected.csv (the trajectory in `sac-lsp rollout`'s
format, values printed with repr so they parse back exactly).
Usage: tests/reference/make_fixture.py --task ant-v5 --seed 3 --steps 300 --out sim/tests/data/ant_v5
Needs gymnasium[mujoco]==1.4.0 and mujoco==3.17.0.
"""
import argparse

import gymnasium as gym
import numpy as np

GYM_IDS = {"ant-v5": "Ant-v5", "inverted-pendulum": "InvertedPendulum-v5"}
TERMS = {"ant-v5": ["x_velocity", "reward_forward", "reward_ctrl", "reward_contact", "reward_survive"],
         "inverted-pendulum": ["reward_survive"]}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--task", required=True, choices=sorted(GYM_IDS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    env = gym.make(GYM_IDS[a.task])
    obs, _ = env.reset(seed=a.seed)
    u = env.unwrapped
    init = np.concatenate([u.data.qpos, u.data.qvel])
    rng = np.random.default_rng(a.seed)
    actions = rng.uniform(env.action_space.low, env.action_space.high,
                          size=(a.steps, env.action_space.shape[0])).astype(np.float64)
    fmt = lambda xs: ",".join(repr(float(x)) for x in xs)
    with open(a.out + ".init.csv", "w") as f:
        f.write(fmt(init) + "\n")
    with open(a.out + ".actions.csv", "w") as f:
        f.write(",".join(f"a{i}" for i in range(actions.shape[1])) + "\n")
        f.writelines(fmt(row) + "\n" for row in actions)
    terms = TERMS[a.task]
    with open(a.out + ".expected.csv", "w") as f:
        f.write(",".join(["t"] + [f"obs_{i}" for i in range(len(obs))] + ["reward", "terminated", "truncated"] + terms) + "\n")
        f.write(f"0,{fmt(obs)},0.0,0,0,{fmt([0.0] * len(terms))}\n")
        for t, act in enumerate(actions):
            obs, r, term, trunc, info = env.step(act)
            f.write(f"{t + 1},{fmt(obs)},{float(r)!r},{int(term)},{int(trunc)},{fmt([info[k] for k in terms])}\n")


if __name__ == "__main__":
    main()
