#!/usr/bin/env bash
# The distributed run on one machine: param server, replay server, learner, N executors and a
# monitor, under one run id and one run file, each process logging to runs/<run-id>/<role>.log.
#
#   deploy/local.sh [N] [RUN_FILE]        N executors (default 8), run file (default deploy/configs/ant-v5.toml)
#
# Environment: RUN_ID (default local-<time>; reuse one to resume its learner checkpoint), PORT (the
# replay server's, default 7447), MINUTES (stop cleanly after that long; default: until Ctrl-C),
# EXECUTOR_NICE (default 10: executors, and the learner's evaluation thread, yield the CPU to the
# learner's updates and the replay server), LEARNER_CORE (default 0 on machines with 2+ cores: the
# learner's update thread gets that core to itself and every other process and thread runs on the
# rest, since the learner's updates/s decide the run; `none` = no pinning), BUILD=0 (skip `cargo build`).
# Ctrl-C or TERM stops exactly this script's children, cleanly (each writes its report), within 30 s.
# Supervision: any role that dies is restarted from its own state while the others go on: the
# learner from its newest checkpoint, the replay server from its snapshot (when the run file gives
# [replay_server] snapshot_path, or DURABLE=1), the param server from the learner's re-sent weights
# and the executors' reports, an executor as a fresh process that joins with the current weights
# (and, with DURABLE=1, re-sends its spool), the monitor appending to its record. Restarts wait 1, 2,
# 4 ... 30 s (doubling per restart of that role) and are capped at RESTARTS per role (default 5);
# past the cap the run stops, exiting non-zero and naming the role. A learner that exits 0 has
# reached max_updates: the run ends there. Every restart is a "local.sh: restart" line on stderr and in
# runs/<run-id>/supervisor.log ("<unix time> restart <role> <count> <exit status>").
# DURABLE=1: no produced transition is lost: the replay server snapshots to runs/<run-id>/replay.snap
# (every [replay_server] snapshot_interval_s) and executors keep what it has not yet made durable in
# runs/<run-id>/spool/ (see README "Durable experience").
# DETERMINISTIC=1: deterministic mode whatever the run file's [train] deterministic says: the N
# executors, the learner and the replay server follow [lockstep]'s schedule, so the same run file
# and seed give bit-identical parameters, and the replay server snapshots its state at every
# learner checkpoint into runs/<run-id>/replay.snap, so that the same RUN_ID resumes exactly from
# the last checkpoint (README "Deterministic mode"); a run file with deterministic = true gets the
# same. There a role that dies restarts the whole run from its last cut (one role cannot rejoin the
# others off it). At the end local.sh prints the SHA-256 of the newest learner checkpoint either way,
# and where the best-evaluated weights are (runs/<run-id>/checkpoints/best-policy.safetensors).
# AUTH=1: an authenticated run: deploy/certs.sh makes runs/<run-id>/auth/ (a CA of the run's own, a
# certificate per role, and per role a zenoh config with mutual TLS and access control), every role
# talks over tls/ endpoints with its role's certificate, and only the learner may publish weights,
# only executors experience, and the monitor only listens (see README "Authenticated runs").
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source deploy/stop_pids.sh

n=${1:-8}
config=${2:-deploy/configs/ant-v5.toml}
[[ $n =~ ^[0-9]+$ && $n -ge 1 ]] || { echo "local.sh: N must be a positive integer, got '$n'" >&2; exit 2; }
[[ -f $config ]] || { echo "local.sh: no run file $config" >&2; exit 2; }
run_id=${RUN_ID:-local-$(date +%Y%m%d-%H%M%S)}
port=${PORT:-7447}
nice_level=${EXECUTOR_NICE:-10}
dir="runs/$run_id"
mkdir -p "$dir"

./deploy/setup.sh
if [[ ${BUILD:-1} != 0 ]]; then
    cargo build --release -p replay-server -p param-server -p learner -p executor -p sac-lsp-cli
fi
bin=target/release
scheme=tcp
if [[ ${AUTH:-0} == 1 ]]; then
    scheme=tls
    [[ -f $dir/auth/ca.pem ]] || ./deploy/certs.sh "$dir/auth"
fi
hub="$scheme/127.0.0.1:$port"
common=(--run-id "$run_id" --config "$config")
peer=(--connect "$hub" --listen "$scheme/127.0.0.1:0")
# The zenoh config of a role's certificate (authenticated runs), as arguments.
auth() {
    [[ $scheme == tls ]] && echo "--zenoh-config $dir/auth/$1.json5"
    return 0
}
export SACLSP_CHECKPOINT_DIR="$dir/checkpoints"
# Deterministic mode's executor set is the one started here (read only in that mode).
export SACLSP_EXECUTORS=$n
# Deterministic mode: DETERMINISTIC=1, or the run file's [train] deterministic = true unless
# SACLSP_DETERMINISTIC says otherwise (set by hand, it decides alone, and gives no replay snapshot).
if [[ ${DETERMINISTIC:-0} == 1 ]] || { [[ -z ${SACLSP_DETERMINISTIC:-} ]] &&
    grep -Eq '^[[:space:]]*deterministic[[:space:]]*=[[:space:]]*true' "$config"; }; then
    # The replay server's snapshot holds its state at each checkpoint: what the run resumes from.
    export SACLSP_DETERMINISTIC=1 SACLSP_REPLAY_SNAPSHOT="$dir/replay.snap"
fi
deterministic=${SACLSP_DETERMINISTIC:-0}
if [[ ${DURABLE:-0} == 1 ]]; then
    export SACLSP_REPLAY_SNAPSHOT="$dir/replay.snap" SACLSP_SPOOL_DIR="$dir/spool"
fi

# CPU placement: one core for the learner's update thread, the others for everything else.
cores=$(nproc)
learner_core=${LEARNER_CORE:-0}
rest=()
if [[ $cores -ge 2 && $learner_core != none ]] && command -v taskset >/dev/null; then
    others=$(seq 0 $((cores - 1)) | grep -vx "$learner_core" | paste -sd,)
    rest=(taskset -c "$others")
else
    learner_core=none
fi

# Moves the learner's update thread onto its core and renices its evaluation thread, once they exist.
place_learner_threads() {
    local pid=$1 placed=0
    # Up to 20 s: a resuming learner first loads its checkpoint (and in deterministic mode asks the
    # replay server, itself loading its snapshot, where to resume).
    for _ in $(seq 400); do
        kill -0 "$pid" 2>/dev/null || return 0 # it died; the main loop reports it
        for task in /proc/"$pid"/task/*; do
            case $(cat "$task/comm" 2>/dev/null) in
                update) [[ $learner_core != none ]] && taskset -p -c "$learner_core" "${task##*/}" >/dev/null && placed=1 ;;
                evaluate) renice -n "$nice_level" -p "${task##*/}" >/dev/null ;;
            esac
        done
        if [[ $placed == 1 ]]; then
            echo "local.sh: learner update thread on core $learner_core, everything else on $others" >&2
            return 0
        fi
        [[ $learner_core == none ]] && return 0
        sleep 0.05
    done
    echo "local.sh: the learner's update thread did not appear; not pinned" >&2
}

declare -A names=() restarts=() due=()
pids=()
start() { # name, command...
    local name=$1
    shift
    "$@" >>"$dir/$name.log" 2>&1 &
    pids+=($!)
    names[$!]=$name
}
# Starts role $1 (replay-server, param-server, learner, monitor or executor-<id>).
launch() {
    case $1 in
        replay-server) start "$1" "${rest[@]}" "$bin/replay-server" "${common[@]}" --listen "$hub" $(auth replay) ;;
        param-server) start "$1" "${rest[@]}" "$bin/param-server" "${common[@]}" "${peer[@]}" $(auth param) ;;
        learner)
            start "$1" "${rest[@]}" "$bin/learner" "${common[@]}" "${peer[@]}" $(auth learner)
            place_learner_threads "${pids[-1]}"
            ;;
        monitor) start "$1" "${rest[@]}" "$bin/sac-lsp" monitor --run-id "$run_id" "${peer[@]}" --out "$dir/monitor.jsonl" $(auth monitor) ;;
        executor-*)
            start "$1" "${rest[@]}" nice -n "$nice_level" "$bin/executor" "${common[@]}" --id "${1#executor-}" "${peer[@]}" $(auth executor)
            ;;
    esac
}

# The newest learner checkpoint and its SHA-256: two deterministic runs end with the same one. Then
# the best-evaluated weights (learner/src/best.rs), which a long run's newest checkpoint may not be.
report_parameters() {
    local newest best="$dir/checkpoints/best-policy"
    newest=$(ls "$dir/checkpoints"/learner-*.safetensors 2>/dev/null | tail -n 1)
    [[ -n $newest ]] || return 0
    echo "local.sh: parameters $(sha256sum "$newest" | cut -d' ' -f1) in $newest" >&2
    [[ -f $best.toml ]] || return 0
    echo "local.sh: best policy in $best.safetensors, its evaluation:" \
        "$(grep -E '^(learner_step|episodes|mean_return)' "$best.toml" | tr '\n' ' ')" >&2
}

stopping=0
stop_all() {
    stopping=1
    stop_pids "local.sh: some roles" "${pids[@]}"
}
trap 'echo "local.sh: stopping $run_id" >&2; stop_all; exit 130' INT TERM

echo "local.sh: run $run_id, $n executors, run file $config, logs in $dir/" >&2
roles=(replay-server param-server learner $(seq -f 'executor-%g' 0 $((n - 1))) monitor)
for role in "${roles[@]}"; do
    launch "$role"
done
echo "local.sh: live view: $bin/sac-lsp monitor --run-id $run_id --connect $hub --out $dir/view.jsonl --no-tensorboard $(auth monitor)" >&2

deadline=""
[[ -n ${MINUTES:-} ]] && deadline=$(($(date +%s) + ${MINUTES%.*} * 60))
max_restarts=${RESTARTS:-${EXECUTOR_RESTARTS:-5}}
while true; do
    now=$(date +%s)
    # In launch order: a whole deterministic run restarting starts its replay server first.
    for name in "${roles[@]}"; do
        if [[ -n ${due[$name]:-} && ${due[$name]} -le $now ]]; then
            unset "due[$name]"
            launch "$name"
        fi
    done
    for pid in "${pids[@]}"; do
        kill -0 "$pid" 2>/dev/null && continue
        status=0
        wait "$pid" || status=$?
        name=${names[$pid]}
        remaining=()
        for p in "${pids[@]}"; do [[ $p != "$pid" ]] && remaining+=("$p"); done
        pids=("${remaining[@]}")
        echo "local.sh: $name (pid $pid) exited with status $status; see $dir/$name.log" >&2
        if [[ $name == learner && $status == 0 ]]; then # max_updates reached
            stop_all
            report_parameters
            exit 0
        fi
        restarts[$name]=$((${restarts[$name]:-0} + 1))
        count=${restarts[$name]}
        if [[ $count -gt $max_restarts ]]; then
            echo "local.sh: $name died more than $max_restarts times; stopping the run" >&2
            # The error, not a backtrace: anyhow prints "Error: ..." first.
            grep -m1 -A3 '^Error' "$dir/$name.log" >&2 || tail -n 5 "$dir/$name.log" >&2 || true
            stop_all
            exit 1
        fi
        wait_s=$((1 << (count - 1)))
        [[ $wait_s -gt 30 ]] && wait_s=30
        echo "$now restart $name $count $status" >>"$dir/supervisor.log"
        if [[ $deterministic == 1 && $name != monitor ]]; then
            # A deterministic run's roles agree on one cut; one role cannot rejoin the others off it,
            # so the whole run restarts from its newest cut.
            echo "local.sh: restart $count of $name: deterministic mode restarts the whole run from its last cut in $wait_s s" >&2
            stop_all
            pids=()
            for role in "${roles[@]}"; do
                due[$role]=$((now + wait_s))
            done
            break
        fi
        due[$name]=$((now + wait_s))
        echo "local.sh: restart $count of $name in $wait_s s (from its own state); the others go on" >&2
    done
    if [[ -n $deadline && $now -ge $deadline ]]; then
        echo "local.sh: $MINUTES minutes are up; stopping $run_id" >&2
        stop_all
        report_parameters
        [[ -x $bin/sac-lsp ]] && "$bin/sac-lsp" plot --input "$dir/monitor.jsonl" --out-dir "$dir" || true
        exit 0
    fi
    sleep 1
done
