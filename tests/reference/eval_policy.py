#!/usr/bin/env python3
"""Evaluates a SAC-LSP policy in Gymnasium, outside the project: NumPy for the networks, Gymnasium's
own Ant-v5 (mujoco 3.17.0) for the environment. Nothing of the project's code runs here, so a
result it prints checks the project's evaluator and environment too.

    python3 tests/reference/eval_policy.py CHECKPOINT [--episodes 20] [--latent zero|fixed|stochastic]
        [--env Ant-v5] [--seed 0] [--json OUT]

CHECKPOINT is a learner checkpoint or weights snapshot (safetensors with `policy.*` tensors). A
hierarchy's checkpoint also holds its frozen levels as `frozen.<k>.policy.*` (k = 0 env-facing): the
trained level's output h (no tanh, linear embedding output) then drives each frozen level in turn,
a = f_k(h; E_k(s)), with the tanh at level 0 only (`docs/sac-lsp.md` §9).
The policy is read from the tensor names alone (`docs/sac-lsp.md` §1): an MLP embedding c = E(s) (ReLU
hidden; the output ReLU unless --linear-embedding-output), then real-NVP coupling layers in index
order (layer i even: moves x[:D/2] conditioned on [x[D/2:], c]; odd: moves x[D/2:] conditioned on
[x[:D/2], c]; x_M <- x_M exp(s(u)) + t(u), s and t tanh-hidden, linear-output MLPs), then a = tanh(y).
--latent zero evaluates h = 0 (the counterpart of a Gaussian policy's mean action), fixed one
h ~ N(0, I) held for all episodes (the paper's), stochastic a fresh z every step.
Needs: pip install "gymnasium[mujoco]" mujoco==3.17.0
"""

import argparse
import json
import re
import struct
import sys

import numpy as np


def read_safetensors(path):
    with open(path, "rb") as f:
        raw = f.read()
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8 : 8 + n])
    data = raw[8 + n :]
    dtypes = {"F32": np.float32, "F64": np.float64, "I64": np.int64}
    out = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        lo, hi = info["data_offsets"]
        out[name] = np.frombuffer(data[lo:hi], dtype=dtypes[info["dtype"]]).reshape(info["shape"])
    return out


def mlp_layers(tensors, prefix):
    layers, k = [], 0
    while f"{prefix}layer{k}.weight" in tensors:
        layers.append((tensors[f"{prefix}layer{k}.weight"].astype(np.float64), tensors[f"{prefix}layer{k}.bias"]))
        k += 1
    if not layers:
        sys.exit(f"no layers under {prefix!r}: not a SAC-LSP policy")
    return layers


def mlp(layers, x, hidden, output):
    for k, (w, b) in enumerate(layers):
        x = x @ w.T + b
        x = output(x) if k == len(layers) - 1 else hidden(x)
    return x


class Policy:
    def __init__(self, tensors, linear_output, squash=True):
        self.squash = squash
        self.embedding = mlp_layers(tensors, "policy.embedding.")
        self.out_act = (lambda x: x) if linear_output else (lambda x: np.maximum(x, 0.0))
        idx = sorted({int(m.group(1)) for n in tensors for m in [re.match(r"policy\.coupling(\d+)\.", n)] if m})
        self.couplings = [
            (i, mlp_layers(tensors, f"policy.coupling{i}.scale."), mlp_layers(tensors, f"policy.coupling{i}.translation."))
            for i in idx
        ]
        self.obs_dim = self.embedding[0][0].shape[1]
        # The action dimension: the kept plus moved widths of any coupling layer.
        i, scale, _ = self.couplings[0]
        moved = scale[-1][0].shape[0]
        kept = scale[0][0].shape[1] - self.embedding[-1][0].shape[0]
        self.act_dim = moved + kept

    def act(self, obs, z):
        relu = lambda x: np.maximum(x, 0.0)
        c = mlp(self.embedding, obs.astype(np.float32).astype(np.float64), relu, self.out_act)
        x = z.astype(np.float64).copy()
        split = self.act_dim // 2
        for i, scale, trans in self.couplings:
            moved, kept = (slice(0, split), slice(split, None)) if i % 2 == 0 else (slice(split, None), slice(0, split))
            u = np.concatenate([x[kept], c])
            s = mlp(scale, u, np.tanh, lambda v: v)
            t = mlp(trans, u, np.tanh, lambda v: v)
            x[moved] = x[moved] * np.exp(s) + t
        return np.tanh(x) if self.squash else x


class Stack:
    """The trained level on top of the frozen levels the checkpoint carries (none: a plain policy)."""

    def __init__(self, tensors, linear_output):
        self.frozen = []
        while any(n.startswith(f"frozen.{len(self.frozen)}.") for n in tensors):
            k = len(self.frozen)
            level = {n[len(f"frozen.{k}.") :]: t for n, t in tensors.items() if n.startswith(f"frozen.{k}.")}
            self.frozen.append(Policy(level, linear_output=k > 0, squash=k == 0))
        top_linear = linear_output or bool(self.frozen)
        self.top = Policy(tensors, top_linear, squash=not self.frozen)
        self.obs_dim, self.act_dim = self.top.obs_dim, self.top.act_dim

    def act(self, obs, z):
        h = self.top.act(obs, z)
        for level in reversed(self.frozen):
            h = level.act(obs, h)
        return h


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--latent", choices=["zero", "fixed", "stochastic"], default="zero")
    ap.add_argument("--env", default="Ant-v5")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--linear-embedding-output", action="store_true")
    ap.add_argument("--json", help="write the summary here too")
    args = ap.parse_args()

    import gymnasium as gym

    policy = Stack(read_safetensors(args.checkpoint), args.linear_embedding_output)
    env = gym.make(args.env)
    assert env.observation_space.shape == (policy.obs_dim,), (env.observation_space.shape, policy.obs_dim)
    low, high = env.action_space.low, env.action_space.high
    rng = np.random.default_rng(args.seed)
    fixed = rng.standard_normal(policy.act_dim)
    returns, lengths = [], []
    for ep in range(args.episodes):
        obs, _ = env.reset(seed=args.seed + ep)
        total, steps, done = 0.0, 0, False
        while not done:
            z = {"zero": np.zeros(policy.act_dim), "fixed": fixed}.get(args.latent)
            if z is None:
                z = rng.standard_normal(policy.act_dim)
            a = policy.act(obs, z).astype(np.float32)
            action = (low + high) / 2 + a.astype(np.float64) * (high - low) / 2
            obs, reward, terminated, truncated, _ = env.step(action)
            total += reward
            steps += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(steps)
        print(f"episode {ep}: return {total:.1f}, length {steps}", file=sys.stderr)
    r = np.array(returns)
    summary = {
        "checkpoint": args.checkpoint,
        "env": args.env,
        "latent": args.latent,
        "frozen_levels": len(policy.frozen),
        "episodes": args.episodes,
        "mean": float(r.mean()),
        "std": float(r.std()),
        "stderr": float(r.std(ddof=1) / np.sqrt(len(r))) if len(r) > 1 else 0.0,
        "min": float(r.min()),
        "max": float(r.max()),
        "median": float(np.median(r)),
        "mean_length": float(np.mean(lengths)),
        "returns": [round(float(x), 1) for x in r],
        "lengths": [int(n) for n in lengths],
    }
    print(json.dumps(summary))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
