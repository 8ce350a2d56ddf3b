#!/usr/bin/env bash
# A fault soak: the distributed run with durable experience (local.sh DURABLE=1, every role
# supervised), while roles are killed with SIGKILL at random times from a seeded schedule; at the
# end one summary: experience produced, stored, refused, dropped by reason, pending, lost at a
# kill (in a killed executor's memory, counted by its made marks) and unexplained (must be 0),
# restarts per role, the learner's step around each of its kills (never back past its last
# checkpoint), the longest wait any role logged, whether the learner still updates, exit status.
#
#   deploy/soak.sh [MINUTES] [RUN_FILE]        (default 30 minutes, deploy/configs/soak.toml)
#
# Environment: EXECUTORS (default 4), SEED (the kill schedule's, default 1), KILL_EVERY_S (a kill
# every KILL_EVERY_S/2 .. 3*KILL_EVERY_S/2 seconds, default 40), WAIT_DEADLINE_S (a logged wait
# longer than this fails the soak, default 120), RUN_ID (default soak-<time>), BUILD=0 (skip the
# build). No kills in the last two minutes: the run must show that it recovered. Exits non-zero if
# the experience audit found anything unexplained, a wait passed its deadline, the learner stopped
# updating or local.sh failed.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

minutes=${1:-30}
config=${2:-deploy/configs/soak.toml}
[[ $minutes =~ ^[0-9]+$ && $minutes -ge 3 ]] || { echo "soak.sh: MINUTES must be an integer >= 3, got '$minutes'" >&2; exit 2; }
[[ -f $config ]] || { echo "soak.sh: no run file $config" >&2; exit 2; }
n=${EXECUTORS:-4}
every=${KILL_EVERY_S:-40}
run_id=${RUN_ID:-soak-$(date +%Y%m%d-%H%M%S)}
dir=runs/$run_id
bin=target/release
mkdir -p "$dir"
./deploy/setup.sh
if [[ ${BUILD:-1} != 0 ]]; then
    cargo build --release -p replay-server -p param-server -p learner -p executor -p sac-lsp-cli \
        -p cluster
fi

RESTARTS=1000000 DURABLE=1 RUN_ID=$run_id MINUTES=$minutes BUILD=0 ./deploy/local.sh "$n" "$config" \
    >"$dir/local.out" 2>&1 &
local_pid=$!
trap 'kill -TERM $local_pid 2>/dev/null; wait $local_pid; exit 130' INT TERM
echo "soak.sh: run $run_id, $n executors, $minutes minutes, kills from seed ${SEED:-1}; logs in $dir/" >&2

# The running process of role $1 (replay-server, param-server, learner, executor-<id>).
pid_of() {
    case $1 in
        executor-*) pgrep -f "$bin/executor --run-id $run_id --config $config --id ${1#executor-} " || true ;;
        *) pgrep -f "$bin/$1 --run-id $run_id " || true ;;
    esac
}
# The learner step of the monitor's newest tick.
last_step() { tail -n 200 "$dir/monitor.jsonl" 2>/dev/null | grep -o '"learner_step":[0-9]*' | tail -n 1 | cut -d: -f2; }

RANDOM=${SEED:-1}
roles=(replay-server param-server learner executor)
stop_killing=$(($(date +%s) + minutes * 60 - 120))
: >"$dir/kills.log"
while kill -0 "$local_pid" 2>/dev/null; do
    sleep $((every / 2 + RANDOM % (every + 1)))
    [[ $(date +%s) -lt $stop_killing ]] || break
    role=${roles[RANDOM % ${#roles[@]}]}
    [[ $role == executor ]] && role=executor-$((RANDOM % n))
    pid=$(pid_of "$role" | head -n 1)
    if [[ -z $pid ]]; then
        echo "$(date +%s) skip $role (not running: restarting)" >>"$dir/kills.log"
        continue
    fi
    checkpoint=$(ls "$dir/checkpoints" 2>/dev/null | sed -n 's/^learner-0*\([0-9][0-9]*\)\.safetensors$/\1/p' | sort -n | tail -n 1)
    step=$(last_step)
    kill -KILL "$pid" 2>/dev/null || true
    echo "$(date +%s) kill $role pid=$pid step=${step:-0} checkpoint=${checkpoint:-0}" >>"$dir/kills.log"
    echo "soak.sh: killed $role (pid $pid) at learner step ${step:-0}" >&2
done
status=0
wait "$local_pid" || status=$?

audit=$(RUST_LIB_BACKTRACE=0 "$bin/experience-audit" --config "$config" --snapshot "$dir/replay.snap" --spool "$dir/spool" --executors "$n" 2>&1) \
    && audit_status=0 || audit_status=$?
python3 deploy/soak_summary.py "$dir" "$status" "$audit_status" "${WAIT_DEADLINE_S:-120}" "$audit"
