#!/usr/bin/env python3
"""deploy/scale.sh's measuring hand: waits on a row's monitor record, samples the processes, and
turns a row's record and samples into a table row; checks the partition test.

    scale_summary.py header
    scale_summary.py wait-ready MONITOR_JSONL N DEADLINE_S
    scale_summary.py wait-rejoined MONITOR_JSONL N HEAL_UNIX_MS DEADLINE_S
    scale_summary.py probe NETNS LINK PARAM_PID EXECUTOR_PID...  (JSON on stdout)
    scale_summary.py row DIR RUN_FILE N MODE DELAY_MS              (a markdown row on stdout)
    scale_summary.py partition DIR CUT_MS HEAL_MS HEALED AUDIT_STATUS   (exits 1 unless it passed)

Executor i runs on host B, C or D as i % 3 is 0, 1 or 2 (scale.sh's round-robin).
"""

import json
import os
import re
import statistics
import subprocess
import sys
import time
import tomllib

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def ticks(path):
    """The monitor record's ticks, in order (a line still being written is skipped)."""
    out = []
    try:
        with open(path) as f:
            for line in f:
                try:
                    record = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if record.get("type") == "tick":
                    out.append(record)
    except FileNotFoundError:
        pass
    return out


def ready(tick, n):
    alive = [e for e in tick["executors"] if e["alive"] and (e.get("env_steps") or 0) > 0]
    return (tick.get("learner_step") or 0) > 0 and len(alive) >= n


def wait_ready(path, n, deadline_s):
    end = time.time() + deadline_s
    while time.time() < end:
        t = ticks(path)
        if t and ready(t[-1], n):
            return 0
        time.sleep(1)
    last = ticks(path)[-1:] or [None]
    print(f"not ready within {deadline_s} s; last tick: {json.dumps(last[0])[:400]}", file=sys.stderr)
    return 1


def host_of(executor_id):
    return "BCD"[executor_id % 3]


def wait_rejoined(path, n, heal_ms, deadline_s):
    """Every executor alive again after the heal, and host C's stepping past where they stood."""
    end = time.time() + deadline_s
    while time.time() < end:
        t = ticks(path)
        before = {e["id"]: e.get("env_steps") or 0 for x in t if x["unix_ms"] <= heal_ms for e in x["executors"]}
        for x in (x for x in t if x["unix_ms"] > heal_ms):
            c = [e for e in x["executors"] if host_of(e["id"]) == "C"]
            if ready(x, n) and c and all((e.get("env_steps") or 0) > before.get(e["id"], 0) for e in c):
                print(f"rejoined {(x['unix_ms'] - heal_ms) / 1000:.1f} s after the heal", file=sys.stderr)
                return 0
        time.sleep(1)
    print(f"host C's executors did not rejoin within {deadline_s} s of the heal", file=sys.stderr)
    return 1


def sockets_sent(netns, pid):
    """bytes_sent of every TCP socket of `pid` in `netns`, by (local, peer) address."""
    out = subprocess.run(
        ["ip", "netns", "exec", netns, "ss", "-tinpH"], capture_output=True, text=True, check=True
    ).stdout
    sent, key = {}, None
    for line in out.splitlines():
        if line and not line[0].isspace():
            fields = line.split()
            key = (fields[3], fields[4]) if f"pid={pid}," in line else None
        elif key is not None:
            m = re.search(r"bytes_sent:(\d+)", line)
            if m:
                sent[f"{key[0]} {key[1]}"] = int(m.group(1))
            key = None
    return sent


def cpu_seconds(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS  # utime + stime
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return None


def link_tx_bytes(netns, link):
    """Bytes `link` (host A's side of its link to the others) has sent."""
    out = subprocess.run(
        ["ip", "netns", "exec", netns, "cat", f"/sys/class/net/{link}/statistics/tx_bytes"],
        capture_output=True, text=True, check=True,
    ).stdout
    return int(out.strip())


def probe(netns, link, param_pid, executor_pids):
    return {
        "unix_ms": int(time.time() * 1000),
        "host_tx_bytes": link_tx_bytes(netns, link),
        "param_sockets": sockets_sent(netns, param_pid),
        "executor_cpu_s": {p: cpu_seconds(p) for p in executor_pids},
    }


def pct(values, q):
    if not values:
        return float("nan")
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q * (len(values) - 1))))]


HEADER = (
    "| run file | executors | weights | one-way delay | env steps/s | per executor | learner updates/s "
    "| weight lag p50 / p95 / max (learner steps) | param server sent, KB/s | per weights version, KB "
    "| host A sent, KB/s | barrier waits | CPU per executor |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def row(directory, run_file, n, mode, delay):
    with open(os.path.join(directory, "probe0.json")) as f:
        p0 = json.load(f)
    with open(os.path.join(directory, "probe1.json")) as f:
        p1 = json.load(f)
    t0, t1 = p0["unix_ms"], p1["unix_ms"]
    window = [x for x in ticks(os.path.join(directory, "monitor.jsonl")) if t0 <= x["unix_ms"] <= t1]
    if len(window) < 2:
        return f"| {run_file} | {n} | {mode} | {delay} ms | no ticks in the window |"
    first, last = window[0], window[-1]
    dt = (last["unix_ms"] - first["unix_ms"]) / 1000
    env = ((last["env_steps_total"] or 0) - (first["env_steps_total"] or 0)) / dt
    updates = ((last["learner_step"] or 0) - (first["learner_step"] or 0)) / dt
    lags = [e["policy_lag_steps"] for x in window for e in x["executors"] if e.get("policy_lag_steps") is not None]
    samples = [e for x in window for e in x["executors"] if e["alive"]]
    waits = sum(1 for e in samples if e.get("blocked")) / max(1, len(samples))
    s0, s1 = p0["param_sockets"], p1["param_sockets"]
    sent = sum(v - s0.get(k, 0) for k, v in s1.items())
    probe_s = (t1 - t0) / 1000
    with open(os.path.join(directory, "run.toml"), "rb") as f:
        every = tomllib.load(f).get("learner", {}).get("publish_weights_every_updates", 100)
    versions = ((last["weights_version"] or 0) - (first["weights_version"] or 0)) / every
    per_version = sent * dt / probe_s / max(versions, 1) / 1024
    host = (p1["host_tx_bytes"] - p0["host_tx_bytes"]) / probe_s / 1024
    cpu = [
        (p1["executor_cpu_s"][p] - c0) / probe_s
        for p, c0 in p0["executor_cpu_s"].items()
        if c0 is not None and p1["executor_cpu_s"].get(p) is not None
    ]
    return (
        f"| {run_file} | {n} | {mode} | {delay} ms | {env:,.0f} | {env / int(n):,.1f} | {updates:,.0f} "
        f"| {pct(lags, 0.5):.0f} / {pct(lags, 0.95):.0f} / {max(lags, default=float('nan')):.0f} "
        f"| {sent / probe_s / 1024:,.1f} | {per_version:,.1f} | {host:,.1f} | {100 * waits:.0f}% "
        f"| {100 * statistics.fmean(cpu):.1f}% |"
    )


def partition(directory, cut_ms, heal_ms, healed, audit_status):
    t = ticks(os.path.join(directory, "monitor.jsonl"))
    at = lambda ms: max((x for x in t if x["unix_ms"] <= ms), key=lambda x: x["unix_ms"], default=None)
    cut, heal = at(cut_ms), at(heal_ms)
    during = [x for x in t if cut_ms < x["unix_ms"] <= heal_ms]
    c_gone = any(not e["alive"] for x in during for e in x["executors"] if host_of(e["id"]) == "C")
    moved = (heal["learner_step"] or 0) - (cut["learner_step"] or 0) if cut and heal else 0
    with open(os.path.join(directory, "audit.txt")) as f:
        audit = f.read()
    lost = re.search(r"unexplained: (\d+)", audit)
    checks = [
        ("the cut took effect: host C's executors were seen gone while it lasted", c_gone),
        (f"the barrier did not deadlock: the learner took {moved:,} steps during the cut", moved > 0),
        ("host C's executors rejoined and stepped on after the heal", healed),
        (
            f"nothing lost: the experience audit passed, unexplained = {lost.group(1) if lost else '?'}",
            audit_status == 0 and lost is not None and lost.group(1) == "0",
        ),
    ]
    print("# Partition test (deploy/scale.sh)\n")
    print("16 executors (tiny networks, real Ant) on hosts B-D, durable experience, host C cut for 30 s.\n")
    for what, ok in checks:
        print(f"- {'PASS' if ok else 'FAIL'}: {what}")
    print("\nThe audit:\n")
    print("\n".join("    " + line for line in audit.strip().splitlines()))
    return 0 if all(ok for _, ok in checks) else 1


def main(argv):
    command, args = argv[1], argv[2:]
    if command == "header":
        print(HEADER)
        return 0
    if command == "wait-ready":
        return wait_ready(args[0], int(args[1]), float(args[2]))
    if command == "wait-rejoined":
        return wait_rejoined(args[0], int(args[1]), int(args[2]), float(args[3]))
    if command == "probe":
        print(json.dumps(probe(args[0], args[1], args[2], args[3:])))
        return 0
    if command == "row":
        print(row(*args))
        return 0
    if command == "partition":
        return partition(args[0], int(args[1]), int(args[2]), args[3] == "1", int(args[4]))
    sys.exit(f"unknown command {command}")


if __name__ == "__main__":
    sys.exit(main(sys.argv))
