#!/usr/bin/env python3
"""Writes the Markdown table of `table.sh`: each row's 200-episode evaluations beside the
dissertation's Table 5.4 figure (rllab Ant, ~10M updates, one seed).

    table.py TASK TABLE_ID UPDATES    (reads runs/<table id>-<row>/eval*.json and train_seconds)
"""
import json
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


def load(table_id, row, name):
    path = pathlib.Path("runs") / f"{table_id}-{row}" / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def cell(e):
    return f"{e['mean']:.1f} ± {e['std']:.1f} (s.e. {e['stderr']:.1f})" if e else "not run"


def main():
    task, table_id, updates = sys.argv[1], sys.argv[2], int(sys.argv[3])
    paper = task == "ant-rllab"
    base = load(table_id, "sac-lsp", "eval")
    print(f"# Table 5.4 on {task}, {updates:,} learner updates per row\n")
    print(f"`deploy/experiments/table.sh {'rllab' if paper else 'v5'}` with UPDATES={updates}, TABLE_ID={table_id}.")
    episodes = base["episodes"] if base else "the same"
    print(f"Each row's final checkpoint evaluated by `sac-lsp eval --seed 0` on {episodes} episodes: with the paper's")
    print("fixed latent (one h ~ N(0, I) for every episode, so the figure hangs on one draw) and with h = 0.")
    print(f"2L: the low level is the distributed row's checkpoint at {updates * 3 // 5:,} updates, the high level")
    print(f"trained {updates * 2 // 5:,} more (its train minutes are the high level's).\n")
    head = "| model | fixed h: mean ± std | min | max | rel. | h = 0: mean ± std | "
    head += "paper (10M updates) | paper rel. | " if paper else ""
    print(head + "train minutes |")
    print("|---|---|---|---|---|---|" + ("---|---|" if paper else "") + "---|")
    ran = [r for r in EXTENSIONS if load(table_id, r[0], "eval")]
    for row, name, figure in ROWS + ran:
        e, zero = load(table_id, row, "eval"), load(table_id, row, "eval-zero")
        seconds = pathlib.Path("runs") / f"{table_id}-{row}" / "train_seconds"
        rel = f"{e['mean'] / base['mean']:.2f}" if e and base else ""
        cells = [cell(e), f"{e['min']:.1f}" if e else "", f"{e['max']:.1f}" if e else "", rel, cell(zero)]
        if paper:
            cells += [f"{figure:.2f}", f"{figure / 3157.40:.2f}"]
        cells.append(f"{int(seconds.read_text()) / 60:.1f}" if seconds.exists() else "")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if ran:
        print("\nThe extensions run on the distributed row's configuration; rel. is still against the")
        print("SAC-LSP row, as the paper's. HER rows report the environment's own reward (as the paper")
        print("does); their goal success rates are in their eval*.json.")
    low, low_zero = load(table_id, "2l-distributed", "eval-low"), load(table_id, "2l-distributed", "eval-low-zero")
    if low:
        print(f"\nThe 2L row's frozen low level alone, evaluated the same way: fixed h {cell(low)}, "
              f"h = 0 {cell(low_zero)}.")


if __name__ == "__main__":
    main()
