cd /work/main
C=deploy/configs/ant-v5-deterministic.toml
DETERMINISTIC=1 RUN_ID=det-k MINUTES=6 BUILD=0 ./deploy/local.sh 8 $C > /tmp/det-k.log 2>&1 &
# kill executor 3 once the learner is past its first cut (step 10,000)
for i in $(seq 120); do
  sleep 1
  s=$(grep -ho '"learner_step":[0-9]*' runs/det-k/monitor.jsonl 2>/dev/null | tail -1 | cut -d: -f2)
  if [[ -n $s && $s -gt 13000 ]]; then pkill -9 -f "executor .*--run-id det-k .*--id 3 " && echo "killed at $s"; break; fi
done
wait
echo KDONE
