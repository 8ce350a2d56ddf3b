"""Updates/s from the first update to the last and env steps per update, from each run's monitor
record (runs/<run>/monitor.jsonl, else the gzipped copy beside this script), and the learner's
time spent waiting for batches (its report line).

python3 docs/results/deterministic/cost.py det-a det-b det-normal
"""
import gzip, json, os, re, sys

here = os.path.dirname(os.path.abspath(__file__))


def lines(run):
    live = f'runs/{run}/monitor.jsonl'
    return open(live) if os.path.exists(live) else gzip.open(f'{here}/{run}.monitor.jsonl.gz', 'rt')


def learner_wait_s(run):
    live = f'runs/{run}/learner.log'
    text = open(live).read() if os.path.exists(live) else open(f'{here}/{run}.learner-report.txt').read()
    waits = re.findall(r'wait_ms_total: (\d+)', text)
    return int(waits[-1]) / 1000 if waits else float('nan')


for run in sys.argv[1:]:
    ticks = [json.loads(l) for l in lines(run)]
    ticks = [t for t in ticks if t['type'] == 'tick' and t['learner_step'] is not None]
    first = next(t for t in ticks if t['learner_step'] > 0)
    top = max(t['learner_step'] for t in ticks)
    last = next(t for t in ticks if t['learner_step'] == top)
    du, dt = last['learner_step'] - first['learner_step'], last['elapsed_s'] - first['elapsed_s']
    env = last['env_steps_total']
    print(f"{run}: updates {first['learner_step']}->{top} in {dt:.1f} s = {du / dt:.0f} updates/s; "
          f"env steps at the end {env}, {env / top:.2f} per update; learner waited {learner_wait_s(run):.1f} s")
