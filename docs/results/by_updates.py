#!/usr/bin/env python3
"""Learning curves of several runs at equal learner updates, as one Markdown table: per bin of
learner steps, each run's mean training-episode return (episodes binned by the weights version they
acted with, which is the learner step of those weights) and the mean of its learner's one-episode
evaluations in that bin. Returns are the task's own reward (also for HER runs).

    python3 docs/results/by_updates.py NAME=runs/<id>/monitor.jsonl[.gz] ... [--bin 10000]
"""

import argparse
import statistics

from windows import lines  # the monitor record's reader, beside this script


def curve(path, width):
    """{bin: (mean training return, episodes, mean eval return, evals)} of one monitor record."""
    train, evals = {}, {}
    for r in lines(path):
        if r["type"] == "episode":
            train.setdefault(r["weights_version"] // width, []).append(r["return"])
        elif r["type"] == "eval":
            evals.setdefault((r["learner_step"] - 1) // width, []).append(r["mean_return"])
    bins = sorted(set(train) | set(evals))
    mean = lambda xs: statistics.fmean(xs) if xs else None
    return {b: (mean(train.get(b, [])), len(train.get(b, [])), mean(evals.get(b, [])), len(evals.get(b, [])))
            for b in bins}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+", help="NAME=monitor record")
    ap.add_argument("--bin", type=int, default=10000)
    args = ap.parse_args()
    named = [r.split("=", 1) for r in args.runs]
    curves = {name: curve(path, args.bin) for name, path in named}
    bins = sorted({b for c in curves.values() for b in c})
    print(f"Mean training-episode return / mean one-episode evaluation per {args.bin:,} learner updates.\n")
    print("| learner updates | " + " | ".join(f"{n}: train | {n}: eval" for n, _ in named) + " |")
    print("|---|" + "---|---|" * len(named))
    fmt = lambda x: "" if x is None else f"{x:.0f}"
    for b in bins:
        cells = []
        for name, _ in named:
            t, _, e, _ = curves[name].get(b, (None, 0, None, 0))
            cells += [fmt(t), fmt(e)]
        print(f"| {b * args.bin:,}-{(b + 1) * args.bin:,} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
