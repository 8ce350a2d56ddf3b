#!/usr/bin/env python3
"""The summary of a fault soak (deploy/soak.sh): reads the run folder it left and prints one report.

    soak_summary.py RUN_DIR LOCAL_STATUS AUDIT_STATUS WAIT_DEADLINE_S AUDIT_TEXT

Exits 1 if the experience audit found a difference nothing explains, a logged wait passed
WAIT_DEADLINE_S, the learner was not updating in the last minute, a learner resumed behind its last
checkpoint, or local.sh failed.
"""
import json
import pathlib
import re
import sys

ANSI = re.compile(r"\x1b\[[0-9;]*m")


def log_lines(path):
    return [ANSI.sub("", line) for line in path.read_text(errors="replace").splitlines()] if path.exists() else []


def main():
    run, local_status, audit_status = pathlib.Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    deadline_ms, audit = float(sys.argv[4]) * 1000, sys.argv[5]
    failed = []

    kills = [line.split() for line in log_lines(run / "kills.log")]
    killed = {}
    for k in kills:
        if k[1] == "kill":
            killed[k[2]] = killed.get(k[2], 0) + 1
    restarts = {}
    for line in log_lines(run / "supervisor.log"):
        _, _, role, _, _ = line.split()
        restarts[role] = restarts.get(role, 0) + 1

    # The learner's start steps, in order: the first start, then one per restart.
    starts = [int(m.group(1)) for line in log_lines(run / "learner.log") if (m := re.search(r"learner up .*step=(\d+)", line))]
    learner_kills = [dict(w.split("=") for w in k[3:]) for k in kills if k[1] == "kill" and k[2] == "learner"]
    resumes = []
    for i, kill in enumerate(learner_kills):
        resumed = starts[i + 1] if i + 1 < len(starts) else None
        ok = resumed is not None and resumed >= int(kill["checkpoint"])
        resumes.append(f"killed at step {kill['step']} (last checkpoint {kill['checkpoint']}), resumed at "
                       f"{resumed if resumed is not None else 'never'}{'' if ok else '  <- BEHIND ITS CHECKPOINT'}")
        if not ok:
            failed.append("a learner resumed behind its last checkpoint")

    waits = []
    for path in sorted(run.glob("*.log")):
        for line in log_lines(path):
            if m := re.search(r"waited_ms=(\d+)", line):
                waits.append((int(m.group(1)), path.stem, line.split("still waiting")[-1].strip()[:120]))
    longest = max(waits, default=None)
    if longest and longest[0] > deadline_ms:
        failed.append(f"a wait of {longest[0] / 1000:.0f} s passed the {deadline_ms / 1000:.0f} s deadline")

    ticks = []
    for line in (run / "monitor.jsonl").read_text().splitlines() if (run / "monitor.jsonl").exists() else []:
        if '"type":"tick"' in line:
            t = json.loads(line)
            ticks.append((t["elapsed_s"], t.get("learner_step") or 0))
    end_s, end_step = ticks[-1] if ticks else (0, 0)
    minute_ago = max((s for e, s in ticks if e <= end_s - 60), default=0)
    updating = end_step > minute_ago
    if not updating:
        failed.append("the learner did not update in the last minute")
    if audit_status != 0:
        failed.append("the experience audit found unexplained transitions (or could not run)")
    if local_status != 0:
        failed.append(f"local.sh exited with status {local_status}")

    print(f"soak summary: {run}")
    print(f"  ran {end_s / 60:.1f} minutes; learner step {end_step} at the end, {end_step - minute_ago} in the last minute")
    print("  experience:")
    for line in audit.splitlines():
        print(f"    {line}")
    print(f"  kills: {sum(killed.values())} ({', '.join(f'{r} {n}' for r, n in sorted(killed.items())) or 'none'})")
    print(f"  restarts: {', '.join(f'{r} {n}' for r, n in sorted(restarts.items())) or 'none'}")
    for r in resumes:
        print(f"  learner {r}")
    if longest:
        print(f"  longest logged wait: {longest[0] / 1000:.1f} s ({longest[1]}: {longest[2]}); "
              f"deadline {deadline_ms / 1000:.0f} s: {'passed' if longest[0] > deadline_ms else 'kept'}")
    else:
        print("  longest logged wait: none logged")
    print(f"  local.sh exit status: {local_status}")
    print(f"  result: {'FAILED: ' + '; '.join(failed) if failed else 'passed'}")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
