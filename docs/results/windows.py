#!/usr/bin/env python3
"""Windowed figures of a monitor record (`runs/<id>/monitor.jsonl`, or its .gz), as the Markdown
tables in docs/results/README.md: per window of wall-clock minutes, the learner's evaluations
(count, mean, max), the mean training-episode return, learner updates/s and env steps/s (medians of
the monitor's ticks), and the learner step and env steps at the window's end.

    python3 docs/results/windows.py runs/<id>/monitor.jsonl [--minutes 2]
"""

import argparse
import gzip
import json
import statistics


def lines(path):
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt") as f:
        for line in f:
            line = line.strip()
            if line:
                yield json.loads(line)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("record")
    ap.add_argument("--minutes", type=float, default=2.0)
    args = ap.parse_args()
    records = list(lines(args.record))
    t0 = min(r["unix_ms"] for r in records if "unix_ms" in r)
    width = args.minutes * 60_000
    windows = {}
    for r in records:
        if "unix_ms" not in r:
            continue
        w = windows.setdefault(int((r["unix_ms"] - t0) // width), {"eval": [], "train": [], "ups": [], "eps": [], "last": None})
        kind = r.get("type")
        if kind == "eval":
            w["eval"].append(r["mean_return"])
            mode = r.get("mode", "fixed_latent")
            w["mode"] = f"{mode} x{r.get('episodes', 1)}"
        elif kind == "episode":
            w["train"].append(r["return"])
        elif kind == "tick":
            if r.get("updates_per_s") is not None:
                w["ups"].append(r["updates_per_s"])
            if r.get("env_steps_per_s_total") is not None:
                w["eps"].append(r["env_steps_per_s_total"])
            w["last"] = r
    fmt = lambda v: "" if v is None else f"{v:,.0f}"
    mean = lambda v: statistics.mean(v) if v else None
    med = lambda v: statistics.median(v) if v else None
    print("| minutes | evaluations | mean eval return | max eval return | mean train-episode return | updates/s | env steps/s | learner step at end | env steps at end |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k in sorted(windows):
        w = windows[k]
        last = w["last"] or {}
        lo, hi = k * args.minutes, (k + 1) * args.minutes
        print(
            f"| {lo:g}-{hi:g} | {len(w['eval'])} | {fmt(mean(w['eval']))} | {fmt(max(w['eval']) if w['eval'] else None)} "
            f"| {fmt(mean(w['train']))} | {fmt(med(w['ups']))} | {fmt(med(w['eps']))} "
            f"| {fmt(last.get('learner_step'))} | {fmt(last.get('env_steps_total'))} |"
        )
    modes = {w.get("mode") for w in windows.values() if w.get("mode")}
    if modes:
        print(f"\nevaluation mode: {', '.join(sorted(modes))}")


if __name__ == "__main__":
    main()
