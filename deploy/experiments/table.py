#!/usr/bin/env python3
"""Writes the Markdown table of `table.sh`: each row's 200-episode evaluations beside the
dissertation's Table 5.4 figure (rllab Ant, ~10M updates, one seed).

    table.py TASK TABLE_ID UPDATES [--records DIR]

Reads each row's records from runs/<table id>-<row>/ (eval.json, eval-zero.json, eval-low*.json,
train_seconds, and the training record: monitor.jsonl of `local.sh`, metrics.csv of `sac-lsp train`);
with --records, from DIR/<row>-<name> instead (the layout committed under docs/results/<table id>/,
where a file may be gzipped: `distributed-monitor.jsonl.gz`). Nothing is trained or evaluated here.

The updates a row really reached are its evaluated checkpoint's `learner_step` (eval.json), not
the budget: a row stopped short of it (MAX_MINUTES, a learner that stopped early) is marked in the
table and named on stderr, and a row with a training record but no evaluation is marked "not
evaluated" with the updates its record reached.
"""
import argparse
import gzip
import json
import math
import pathlib
import sys

# (row, the paper's name, its Table 5.4 average reward; rllab Ant only).
ROWS = [
    ("sac-lsp", "SAC-LSP", 3157.40),
    ("prioritized", "Prioritized SAC-LSP", 4278.88),
    ("distributed", "Distributed SAC-LSP", 4425.76),
    ("2l-distributed", "2L Distributed SAC-LSP", 5173.40),
]
# The extensions, on the distributed row; listed when run. HER: (P)osition or (S)peed goal,
# (B)inary, (S)um-augmented or (P)roportionally-augmented reward (Table 5.4's names).
EXTENSIONS = [
    ("categorical", "Categorical SAC-LSP (soft C51)", 237.02),
    ("categorical-dissertation", "Categorical SAC-LSP (the dissertation's)", 237.02),
    ("her-position-binary", "P.B. HER SAC-LSP", 25.05),
    ("her-position-sum", "P.S. HER SAC-LSP", 1020.32),
    ("her-position-proportional", "P.P. HER SAC-LSP", 1345.33),
    ("her-speed-binary", "S.B. HER SAC-LSP", 32.85),
    ("her-speed-sum", "S.S. HER SAC-LSP", 1146.52),
    ("her-speed-proportional", "S.P. HER SAC-LSP", 1595.57),
]
BASELINE = "sac-lsp"


class Records:
    """A table's records: runs/<table id>-<row>/<name>, or <dir>/<row>-<name>[.gz]."""

    def __init__(self, table_id, records=None):
        self.table_id, self.records = table_id, records

    def path(self, row, name):
        if self.records is None:
            base = pathlib.Path("runs") / f"{self.table_id}-{row}" / name
        else:
            base = pathlib.Path(self.records) / f"{row}-{name}"
        for path in (base, base.with_name(base.name + ".gz")):
            if path.exists():
                return path
        return None

    def text(self, row, name):
        path = self.path(row, name)
        if path is None:
            return None
        data = path.read_bytes()
        return (gzip.decompress(data) if path.suffix == ".gz" else data).decode()

    def json(self, row, name):
        text = self.text(row, name)
        return json.loads(text) if text is not None else None


def training(records, row):
    """(updates, seconds) at the end of a row's training record (None where there is none): the
    monitor's newest learner step of a `local.sh` row, the last epoch of a `sac-lsp train` row."""
    text = records.text(row, "monitor.jsonl")
    if text is not None:
        updates = seconds = None
        for line in text.splitlines():
            try:
                tick = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut off by a stopped monitor
            if tick.get("type") != "tick":
                continue
            seconds = tick.get("elapsed_s", seconds)
            if tick.get("learner_step") is not None:
                updates = max(updates or 0, tick["learner_step"])
        return updates, seconds
    text = records.text(row, "metrics.csv")
    if text is not None:
        lines = [line.split(",") for line in text.splitlines() if line.strip()]
        if len(lines) >= 2:
            head, last = lines[0], lines[-1]
            return int(last[head.index("updates")]), float(last[head.index("wall_s")])
    return None, None


def budget(row, updates):
    """The learner updates a row is given: the 2-level row's high level gets 40% of them."""
    return updates * 2 // 5 if row == "2l-distributed" else updates


def cell(e):
    return f"{e['mean']:.1f} ± {e['std']:.1f} (s.e. {e['stderr']:.1f})" if e else "not run"


def delta(e, base):
    """The difference of two evaluations' means, with its standard error."""
    if not (e and base):
        return ""
    return f"{e['mean'] - base['mean']:+.1f} (s.e. {math.hypot(e['stderr'], base['stderr']):.1f})"


def rel(e, base):
    """The ratio of the means, as the paper's rel.: only where the baseline's mean is positive (a
    ratio to a negative or zero return says nothing)."""
    return f"{e['mean'] / base['mean']:.2f}" if e and base and base["mean"] > 0 else ""


def updates_cell(row, e, zero, records, updates, warnings):
    """The updates the evaluated checkpoint had, marked where short of the row's budget; for a row
    trained but not evaluated, the updates its record reached."""
    want = budget(row, updates)
    steps = {x["learner_step"] for x in (e, zero) if x and x.get("learner_step") is not None}
    if not (e or zero):
        reached, _ = training(records, row)
        if reached is None:
            return ""
        warnings.append(f"{row}: trained to {reached:,} of {want:,} updates, not evaluated")
        return f"**{reached:,} of {want:,}, not evaluated**"
    if not steps:
        reached, _ = training(records, row)  # an evaluation without learner_step: the record's
        return f"{reached:,}?" if reached is not None else "?"
    if len(steps) > 1:
        warnings.append(f"{row}: its evaluations are of different checkpoints ({sorted(steps)})")
        return f"**{' / '.join(f'{s:,}' for s in sorted(steps))}: different checkpoints**"
    (step,) = steps
    if step < want:
        warnings.append(f"{row}: stopped short of its budget, {step:,} of {want:,} updates")
        return f"**{step:,} of {want:,}: short**"
    return f"{step:,}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task")
    parser.add_argument("table_id")
    parser.add_argument("updates", type=int)
    parser.add_argument("--records", help="read DIR/<row>-<name>[.gz] instead of runs/<table id>-<row>/")
    args = parser.parse_args()
    task, table_id, updates = args.task, args.table_id, args.updates
    records = Records(table_id, args.records)
    paper = task == "ant-rllab"
    base = records.json(BASELINE, "eval.json")
    print(f"# Table 5.4 on {task}, {updates:,} learner updates per row\n")
    print(f"`deploy/experiments/table.sh {'rllab' if paper else 'v5'}` with UPDATES={updates}, TABLE_ID={table_id}.")
    if args.records:
        print(f"Written from the records in `{args.records}/` by `deploy/experiments/table.py {task} {table_id} "
              f"{updates} --records {args.records}`;")
        print("train minutes there are the training record's own clock (the monitor's last tick, `sac-lsp train`'s")
        print("last epoch), a few seconds under the wall-clock minutes `table.sh` measures around a row.")
    evals = [records.json(row, "eval.json") for row, _, _ in ROWS + EXTENSIONS]
    episodes = next((e["episodes"] for e in evals if e), "the same")
    print(f"Each row's final checkpoint evaluated by `sac-lsp eval --seed 0` on {episodes} episodes: with the paper's")
    print("fixed latent (one h ~ N(0, I) for every episode, so the figure hangs on one draw) and with h = 0.")
    print(f"2L: the low level is the distributed row's checkpoint at {updates * 3 // 5:,} updates, the high level")
    print(f"trained {updates * 2 // 5:,} more (its train minutes are the high level's).")
    print("updates: the evaluated checkpoint's learner step; a row short of its budget is marked.")
    print("Δ: the fixed-h mean minus the SAC-LSP row's; rel.: their ratio, as the paper's, left blank")
    print("where the SAC-LSP row's mean is not positive.\n")
    head = "| model | updates | fixed h: mean ± std | min | max | Δ vs SAC-LSP | rel. | h = 0: mean ± std | "
    head += "paper (10M updates) | paper rel. | " if paper else ""
    print(head + "train minutes |")
    print("|---|---|---|---|---|---|---|---|" + ("---|---|" if paper else "") + "---|")
    warnings = []
    ran = [r for r in EXTENSIONS if records.json(r[0], "eval.json") or training(records, r[0])[0] is not None]
    for row, name, figure in ROWS + ran:
        e, zero = records.json(row, "eval.json"), records.json(row, "eval-zero.json")
        cells = [updates_cell(row, e, zero, records, updates, warnings), cell(e)]
        cells += [f"{e['min']:.1f}" if e else "", f"{e['max']:.1f}" if e else ""]
        cells += ["–" if row == BASELINE and e else delta(e, base), rel(e, base), cell(zero)]
        if paper:
            cells += [f"{figure:.2f}", f"{figure / 3157.40:.2f}"]
        seconds = records.text(row, "train_seconds")
        seconds = int(seconds) if seconds is not None else training(records, row)[1]
        cells.append(f"{seconds / 60:.1f}" if seconds is not None else "")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if ran:
        print("\nThe extensions run on the distributed row's configuration; Δ and rel. are still against")
        print("the SAC-LSP row, as the paper's. HER rows report the environment's own reward (as the paper")
        print("does); their goal success rates are in their eval*.json.")
    low, low_zero = records.json("2l-distributed", "eval-low.json"), records.json("2l-distributed", "eval-low-zero.json")
    if low:
        at = f" (at {low['learner_step']:,} updates)" if low.get("learner_step") is not None else ""
        print(f"\nThe 2L row's frozen low level alone{at}, evaluated the same way: fixed h {cell(low)}, "
              f"h = 0 {cell(low_zero)}.")
    if warnings:
        print("\nMarked rows: " + "; ".join(warnings) + ".")
        for warning in warnings:
            print(f"table.py: {warning}", file=sys.stderr)


if __name__ == "__main__":
    main()
