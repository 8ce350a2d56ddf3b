#!/usr/bin/env python3
"""Tests of table.py on made-up records and of table.sh with a stand-in `sac-lsp` (no training, about
a second):

    python3 deploy/experiments/test_table.py        (deploy/test.sh runs it)

A row stopped short of its budget and a row trained but not evaluated are marked with the updates
they really reached; rel. is left blank against a baseline whose mean is not positive, and Δ (a
difference) is given either way; committed records (gzipped, <row>-<name>) read the same. table.sh
stops at a row whose training fails instead of evaluating an older checkpoint, and a row stopped
early by MAX_MINUTES reaches the table marked.
"""
import gzip
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = pathlib.Path(__file__).resolve().parent
TABLE = HERE / "table.py"

# Stands in for target/release/sac-lsp: `train` exits with $FAKE_TRAIN_STATUS after writing a checkpoint
# of epoch $FAKE_EPOCHS - 1 (none when the status is not 0); `eval` logs its checkpoint to calls.log and
# prints a summary whose learner_step is that epoch's (1000 per epoch, plus the first update).
FAKE_SAC_LSP = r"""#!/usr/bin/env bash
set -euo pipefail
cmd=$1; shift
case $cmd in
    train)
        while [[ $# -gt 0 ]]; do [[ $1 == --out ]] && out=$2; shift; done
        if [[ ${FAKE_TRAIN_STATUS:-0} == 0 ]]; then
            mkdir -p "$out/checkpoints"
            touch "$out/checkpoints/epoch-$(printf %05d $((FAKE_EPOCHS - 1))).safetensors"
        fi
        exit "${FAKE_TRAIN_STATUS:-0}" ;;
    eval)
        while [[ $# -gt 0 ]]; do [[ $1 == --checkpoint ]] && checkpoint=$2; shift; done
        echo "$checkpoint" >>calls.log
        epoch=$(basename "$checkpoint" .safetensors); epoch=$((10#${epoch#epoch-}))
        echo "{\"learner_step\": $((epoch * 1000 + 1)), \"episodes\": 2, \"mean\": 1.0, \"std\": 1.0, \"stderr\": 1.0, \"min\": 0.0, \"max\": 2.0}" ;;
    *) exit 2 ;;
esac
"""


def evaluation(mean, step, stderr=10.0):
    return {"learner_step": step, "episodes": 200, "mean": mean, "std": 100.0, "stderr": stderr,
            "min": mean - 200, "max": mean + 200}


def tick(step, elapsed):
    return {"type": "tick", "elapsed_s": elapsed, "learner_step": step}


class Table(unittest.TestCase):
    def table(self, task, rows, updates=100000, committed=False):
        """table.py's output and stderr for `rows`: {row: {file name: json object, list of monitor
        ticks, or text}}, written as runs/<table id>-<row>/ or, `committed`, as a records folder."""
        with tempfile.TemporaryDirectory() as cwd:
            folder = pathlib.Path(cwd) / "records"
            for row, files in rows.items():
                for name, content in files.items():
                    if isinstance(content, list):
                        content = "\n".join(json.dumps(t) for t in content) + "\n"
                    elif isinstance(content, dict):
                        content = json.dumps(content)
                    if committed:
                        path = folder / f"{row}-{name}.gz"
                        path.parent.mkdir(parents=True, exist_ok=True)
                        path.write_bytes(gzip.compress(content.encode()))
                    else:
                        path = pathlib.Path(cwd) / "runs" / f"t-{row}" / name
                        path.parent.mkdir(parents=True, exist_ok=True)
                        path.write_text(content)
            args = [sys.executable, str(TABLE), task, "t", str(updates)]
            args += ["--records", str(folder)] if committed else []
            out = subprocess.run(args, cwd=cwd, capture_output=True, text=True, check=True)
            return out.stdout, out.stderr

    @staticmethod
    def row(out, name):
        """The cells of the row named `name`, by column header."""
        lines = [line for line in out.splitlines() if line.startswith("|")]
        head = [c.strip() for c in lines[0].strip("|").split("|")]
        for line in lines[2:]:
            cells = [c.strip() for c in line.strip("|").split("|")]
            if cells[0] == name:
                return dict(zip(head, cells))
        raise AssertionError(f"no row {name!r} in\n{out}")

    def test_a_negative_baseline_gets_no_ratio_but_a_difference(self):
        out, _ = self.table("ant-v5", {
            "sac-lsp": {"eval.json": evaluation(-475.0, 100001), "eval-zero.json": evaluation(46.8, 100001)},
            "distributed": {"eval.json": evaluation(-675.7, 100000), "eval-zero.json": evaluation(229.1, 100000)},
        })
        distributed = self.row(out, "Distributed SAC-LSP")
        self.assertEqual(distributed["rel."], "", "a ratio to a negative mean")
        self.assertTrue(distributed["Δ vs SAC-LSP"].startswith("-200.7"), distributed)
        self.assertEqual(distributed["updates"], "100,000")
        self.assertEqual(self.row(out, "SAC-LSP")["rel."], "")

    def test_a_positive_baseline_keeps_the_ratio(self):
        out, _ = self.table("ant-rllab", {
            "sac-lsp": {"eval.json": evaluation(500.0, 100001)},
            "distributed": {"eval.json": evaluation(1000.0, 100000)},
        })
        distributed = self.row(out, "Distributed SAC-LSP")
        self.assertEqual(distributed["rel."], "2.00")
        self.assertTrue(distributed["Δ vs SAC-LSP"].startswith("+500.0"), distributed)

    def test_a_row_short_of_its_budget_is_marked_with_its_updates(self):
        out, err = self.table("ant-rllab", {
            "sac-lsp": {"eval.json": evaluation(500.0, 61001), "eval-zero.json": evaluation(600.0, 61001)},
            # The 2-level row's budget is 40% of UPDATES: 40,000 is all of it.
            "2l-distributed": {"eval.json": evaluation(700.0, 40000)},
        })
        cells = self.row(out, "SAC-LSP")["updates"]
        self.assertIn("61,001 of 100,000", cells)
        self.assertIn("short", cells)
        self.assertIn("sac-lsp", err)
        self.assertEqual(self.row(out, "2L Distributed SAC-LSP")["updates"], "40,000")

    def test_a_row_trained_but_not_evaluated_shows_what_its_record_reached(self):
        ticks = [tick(None, 0.0), tick(30000, 60.0), tick(52000, 100.0)]
        out, err = self.table("ant-rllab", {
            "distributed": {"monitor.jsonl": ticks},
            "categorical": {"monitor.jsonl": [tick(7000, 10.0)]},
        })
        cells = self.row(out, "Distributed SAC-LSP")["updates"]
        self.assertIn("52,000 of 100,000", cells)
        self.assertIn("not evaluated", cells)
        self.assertIn("not evaluated", self.row(out, "Categorical SAC-LSP (soft C51)")["updates"])
        self.assertIn("distributed", err)

    def test_evaluations_of_different_checkpoints_are_marked(self):
        out, _ = self.table("ant-v5", {
            "distributed": {"eval.json": evaluation(100.0, 100000), "eval-zero.json": evaluation(100.0, 80000)},
        })
        self.assertIn("different checkpoints", self.row(out, "Distributed SAC-LSP")["updates"])

    def test_committed_records_read_the_same(self):
        metrics = "epoch,env_steps,updates,wall_s\n0,1000,1,1.0\n100,101000,100001,612.0\n"
        out, err = self.table("ant-v5", {
            "sac-lsp": {"eval.json": evaluation(-475.0, 100001), "metrics.csv": metrics},
            "distributed": {"eval.json": evaluation(200.0, 100000), "monitor.jsonl": [tick(99990, 319.9)]},
        }, committed=True)
        self.assertEqual(err, "")
        self.assertEqual(self.row(out, "SAC-LSP")["train minutes"], "10.2")
        distributed = self.row(out, "Distributed SAC-LSP")
        self.assertEqual(distributed["train minutes"], "5.3")
        self.assertEqual(distributed["updates"], "100,000")
        self.assertEqual(distributed["rel."], "")


class TableSh(unittest.TestCase):
    """table.sh in a copy of the tree with stand-ins for deploy/setup.sh and target/release/sac-lsp."""

    def setUp(self):
        self.tree = pathlib.Path(tempfile.mkdtemp())
        self.addCleanup(shutil.rmtree, self.tree)
        experiments = self.tree / "deploy" / "experiments"
        experiments.mkdir(parents=True)
        for name in ("table.sh", "table.py", "v5-sac-lsp.toml"):
            shutil.copy(HERE / name, experiments / name)
        (self.tree / "deploy" / "setup.sh").write_text("#!/usr/bin/env bash\n")
        (self.tree / "target" / "release").mkdir(parents=True)
        (self.tree / "target" / "release" / "sac-lsp").write_text(FAKE_SAC_LSP)
        for path in (self.tree / "deploy" / "setup.sh", self.tree / "target" / "release" / "sac-lsp"):
            path.chmod(0o755)
        (self.tree / "docs" / "results").mkdir(parents=True)
        self.row = self.tree / "runs" / "t-sac-lsp"

    def run_table(self, **env):
        env = {**os.environ, "BUILD": "0", "ROWS": "sac-lsp", "UPDATES": "100000", "TABLE_ID": "t",
               "EPISODES": "2", **env}
        script = self.tree / "deploy" / "experiments" / "table.sh"
        return subprocess.run(["bash", str(script), "v5"], cwd=self.tree, env=env, capture_output=True, text=True)

    def evaluated(self):
        calls = self.tree / "calls.log"
        return calls.read_text().split() if calls.exists() else []

    def test_a_failed_row_stops_the_table_instead_of_evaluating_an_older_checkpoint(self):
        # An earlier sitting left a checkpoint; this sitting's training fails.
        (self.row / "checkpoints").mkdir(parents=True)
        (self.row / "checkpoints" / "epoch-00050.safetensors").touch()
        out = self.run_table(FAKE_TRAIN_STATUS="3")
        self.assertEqual(out.returncode, 1, out.stderr)
        self.assertIn("status 3", out.stderr)
        self.assertEqual(self.evaluated(), [], "an older checkpoint was evaluated")
        self.assertFalse((self.tree / "docs" / "results" / "t.md").exists())

    def test_a_time_capped_row_is_marked_in_the_table(self):
        (self.row / "checkpoints").mkdir(parents=True)
        (self.row / "checkpoints" / "epoch-00100.safetensors").touch()  # an earlier, longer sitting
        out = self.run_table(FAKE_EPOCHS="62", MAX_MINUTES="1")
        self.assertEqual(out.returncode, 0, out.stderr)
        self.assertEqual(self.evaluated(), ["runs/t-sac-lsp/checkpoints/epoch-00061.safetensors"] * 2)
        table = (self.tree / "docs" / "results" / "t.md").read_text()
        self.assertIn(Table.row(table, "SAC-LSP")["updates"], "**61,001 of 100,000: short**")
        self.assertIn("stopped short", out.stderr)


if __name__ == "__main__":
    unittest.main()
