import json, sys
# Updates/s from the first update to the last, env steps per update, from each run's monitor record.
for run in sys.argv[1:]:
    ticks=[json.loads(l) for l in open(f'runs/{run}/monitor.jsonl')]
    ticks=[t for t in ticks if t['type']=='tick' and t['learner_step'] is not None]
    first=next(t for t in ticks if t['learner_step']>0)
    last=max(ticks,key=lambda t:(t['learner_step'],-t['elapsed_s']))
    last=next(t for t in ticks if t['learner_step']==last['learner_step'])
    du=last['learner_step']-first['learner_step']; dt=last['elapsed_s']-first['elapsed_s']
    env=last['env_steps_total']
    print(f"{run}: updates {first['learner_step']}->{last['learner_step']} in {dt:.1f} s = {du/dt:.0f} updates/s; env steps at the end {env}, {env/last['learner_step']:.2f} per update")
