#!/usr/bin/env bash
# Executors across machines, measured: four network-namespace "hosts" (A-D) on a bridge of their own,
# a zenoh router per host (`sac-lsp router`), the replay server, param server, learner and monitor on
# host A, and 16, 32 or 64 executors spread round-robin over hosts B-D as clients of their host's
# router, so that what crosses between hosts crosses once per host, as in a real deployment. Each
# link between hosts carries a one-way latency (DELAYS_MS; added by deploy/delay_relay.py on the
# router link, since this machine's kernel has no netem). Per row it prints env steps/s (total, per
# executor), learner updates/s, weight lag, the param server's bytes/s on the wire, barrier waits and
# CPU per executor, then runs the partition test: host C cut off for 30 s and healed, with durable
# experience, checked by the experience audit. Stops by itself; touches only its own namespaces.
#
#   deploy/scale.sh            needs root (ip netns); writes $OUT/table.md and the rows' records
#
# Environment:
#   ROWS       rows "RUN_FILE_NAME:EXECUTORS[:push|:query]" (default "tiny:16 tiny:32 tiny:64 ant-v5:16
#              tiny:16:query tiny:64:query"); tiny = deploy/configs/tiny.toml (tiny networks on the real
#              Ant), ant-v5 = the default run file; :query turns the weights push off (executors ask
#              the param server for every version: the baseline the push is measured against)
#   DELAYS_MS  one-way latencies between hosts, each row is run at each (default "2 20")
#   WINDOW_S   seconds measured per row, once every executor is up and the learner steps (default 40)
#   PARTITION  1 (default): the partition test after the rows; 0: skip it; only: nothing else
#   OUT        where the table and the records go (default docs/results/scale)
#   BUILD=0    skip `cargo build`
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source deploy/stop_pids.sh

[[ $(id -u) == 0 ]] || { echo "scale.sh: needs root (ip netns)" >&2; exit 2; }
command -v ip >/dev/null || { echo "scale.sh: needs ip (iproute2)" >&2; exit 2; }
rows=${ROWS:-"tiny:16 tiny:32 tiny:64 ant-v5:16 tiny:16:query tiny:64:query"}
delays=${DELAYS_MS:-"2 20"}
window=${WINDOW_S:-40}
partition=${PARTITION:-1}
out=${OUT:-docs/results/scale}
bin=target/release
runs=runs/scale-$(date +%Y%m%d-%H%M%S)
mkdir -p "$out" "$runs"

./deploy/setup.sh
if [[ ${BUILD:-1} != 0 ]]; then
    cargo build --release -p replay-server -p param-server -p learner -p executor -p sac-lsp-cli \
        -p cluster --bin experience-audit
fi

# The hosts: namespaces sc<tag>A..D, each joined by a veth pair to a bridge in namespace sc<tag>S.
tag=$(($$ % 10000))
hosts=(A B C D)
ns() { echo "sc${tag}$1"; }
addr() { case $1 in A) echo 10.214.0.1 ;; B) echo 10.214.0.2 ;; C) echo 10.214.0.3 ;; D) echo 10.214.0.4 ;; esac; }
teardown_net() {
    for h in S "${hosts[@]}"; do ip netns del "$(ns "$h")" 2>/dev/null || true; done
}
setup_net() {
    ip netns add "$(ns S)"
    ip -n "$(ns S)" link add br0 type bridge
    ip -n "$(ns S)" link set br0 up
    for h in "${hosts[@]}"; do
        ip netns add "$(ns "$h")"
        ip -n "$(ns "$h")" link set lo up
        ip link add "v$tag$h" type veth peer name "p$tag$h"
        ip link set "v$tag$h" netns "$(ns "$h")"
        ip link set "p$tag$h" netns "$(ns S)"
        ip -n "$(ns S)" link set "p$tag$h" master br0
        ip -n "$(ns S)" link set "p$tag$h" up
        ip -n "$(ns "$h")" addr add "$(addr "$h")/24" dev "v$tag$h"
        ip -n "$(ns "$h")" link set "v$tag$h" up
    done
}

pids=()
cleanup() {
    stop_pids "scale.sh: some processes" "${pids[@]}"
    teardown_net
}
trap 'cleanup; exit 130' INT TERM
trap cleanup EXIT

# Waits (up to 30 s) until something listens on $2 (ADDRESS:PORT) in host $1's namespace.
wait_listening() {
    for _ in $(seq 300); do
        ip netns exec "$(ns "$1")" ss -ltnH "sport = :${2##*:}" | grep -qF "$2" && return 0
        sleep 0.1
    done
    echo "scale.sh: nothing listens on $2 on host $1 after 30 s; see the router's log" >&2
    exit 1
}

# Starts a row's cluster: $1 run id, $2 run file, $3 executors, $4 one-way delay (ms), $5 directory.
# Leaves the pids of the executors in exec_pids, of the param server in param_pid.
start_cluster() {
    local run_id=$1 config=$2 n=$3 delay=$4 dir=$5
    # No shared memory: zenoh hands large messages between processes of one machine through it, and
    # /dev/shm is shared by the namespaces, so it would carry them past the links being measured.
    local noshm=(--zenoh-cfg transport/shared_memory/enabled:false)
    local hub="tcp/$(addr A):7447" common=(--run-id "$1" --config "$2" "${noshm[@]}")
    local peer=(--connect "$hub" --listen tcp/127.0.0.1:0)
    mkdir -p "$dir"
    on_host() { local h=$1 name=$2; shift 2; ip netns exec "$(ns "$h")" "$@" >>"$dir/$name.log" 2>&1 & pids+=($!); }
    on_host A router-A "$bin/sac-lsp" router --listen "$hub" "${noshm[@]}"
    for h in B C D; do
        # Each host's router reaches A's through a relay on its own host, which adds the latency.
        on_host "$h" "relay-$h" python3 deploy/delay_relay.py 127.0.0.1:17447 "$(addr A):7447" "$delay"
        on_host "$h" "router-$h" "$bin/sac-lsp" router --listen tcp/127.0.0.1:7447 --connect tcp/127.0.0.1:17447 \
            "${noshm[@]}"
    done
    SACLSP_CHECKPOINT_DIR="$dir/checkpoints" on_host A replay-server "$bin/replay-server" "${common[@]}" "${peer[@]}"
    on_host A param-server "$bin/param-server" "${common[@]}" "${peer[@]}"
    param_pid=$!
    SACLSP_CHECKPOINT_DIR="$dir/checkpoints" on_host A learner "$bin/learner" "${common[@]}" "${peer[@]}"
    on_host A monitor "$bin/sac-lsp" monitor --run-id "$run_id" "${peer[@]}" --out "$dir/monitor.jsonl" --no-tensorboard --quiet \
        "${noshm[@]}"
    # Executors are zenoh clients, which give up at once when their router is not listening yet.
    for h in B C D; do wait_listening "$h" 127.0.0.1:7447; done
    exec_pids=()
    for i in $(seq 0 $((n - 1))); do
        local h=${hosts[$((1 + i % 3))]}
        on_host "$h" "executor-$i" nice -n 10 "$bin/executor" "${common[@]}" --id "$i" --mode client \
            --connect tcp/127.0.0.1:7447
        exec_pids+=($!)
    done
}

# The run file of a row: the named one, with the weights push off for a :query row, and for the
# durable partition run a replica log that fits the tiny run file's memory budget.
row_config() { # $1 name, $2 push|query|durable, $3 directory
    local source=deploy/configs/$1.toml
    [[ -f $source ]] || { echo "scale.sh: no run file $source" >&2; exit 2; }
    case $2 in
        query) sed 's/^\[executor\]$/[executor]\nweights_push = false/' "$source" ;;
        durable) sed 's/^\[replay_server\]$/[replay_server]\nsnapshot_interval_s = 2\nsnapshot_log_budget_bytes = 16777216/' "$source" ;;
        *) cat "$source" ;;
    esac >"$3/run.toml"
    echo "$3/run.toml"
}

summary=deploy/scale_summary.py
table=$out/table.md
if [[ $partition != only ]]; then
    {
        echo "# deploy/scale.sh on $(lscpu | sed -n 's/^Model name: *//p' | head -n 1), $(nproc) cores, $(date -u +%Y-%m-%d)"
        echo
        python3 "$summary" header
    } >"$table"
    for delay in $delays; do
        for row in $rows; do
            IFS=: read -r name n mode <<<"$row"
            mode=${mode:-push}
            dir="$runs/$name-$n-$mode-${delay}ms"
            mkdir -p "$dir"
            teardown_net
            setup_net
            config=$(row_config "$name" "$mode" "$dir")
            echo "scale.sh: row $name, $n executors, weights by $mode, ${delay} ms between hosts ($dir)" >&2
            pids=()
            start_cluster "scale-$tag-$name-$n-$mode-$delay" "$config" "$n" "$delay" "$dir"
            if ! python3 "$summary" wait-ready "$dir/monitor.jsonl" "$n" 180; then
                echo "scale.sh: row $row did not get every executor up and the learner stepping within 180 s" >&2
                stop_pids "scale.sh: some processes" "${pids[@]}"
                exit 1
            fi
            python3 "$summary" probe "$(ns A)" "v${tag}A" "$param_pid" "${exec_pids[@]}" >"$dir/probe0.json"
            sleep "$window"
            python3 "$summary" probe "$(ns A)" "v${tag}A" "$param_pid" "${exec_pids[@]}" >"$dir/probe1.json"
            stop_pids "scale.sh: some executors" "${exec_pids[@]}"
            stop_pids "scale.sh: some processes" "${pids[@]}"
            python3 "$summary" row "$dir" "$name" "$n" "$mode" "$delay" | tee -a "$table"
        done
    done
    echo "scale.sh: table in $table" >&2
fi

if [[ $partition != 0 ]]; then
    # The partition test: 16 tiny executors with durable experience, host C cut for 30 s, then healed.
    n=16
    dir="$runs/partition"
    mkdir -p "$dir"
    teardown_net
    setup_net
    config=$(row_config tiny durable "$dir")
    echo "scale.sh: partition test: $n executors, host C cut for 30 s ($dir)" >&2
    pids=()
    SACLSP_REPLAY_SNAPSHOT="$dir/replay.snap" SACLSP_SPOOL_DIR="$dir/spool" \
        start_cluster "scale-$tag-partition" "$config" "$n" 2 "$dir"
    python3 "$summary" wait-ready "$dir/monitor.jsonl" "$n" 180 || { echo "scale.sh: partition run did not start" >&2; exit 1; }
    sleep 15
    cut_ms=$(date +%s%3N)
    ip -n "$(ns C)" link set "v${tag}C" down
    sleep 30
    heal_ms=$(date +%s%3N)
    ip -n "$(ns C)" link set "v${tag}C" up
    healed=0
    python3 "$summary" wait-rejoined "$dir/monitor.jsonl" "$n" "$heal_ms" 120 && healed=1
    sleep 10
    stop_pids "scale.sh: some executors" "${exec_pids[@]}"
    stop_pids "scale.sh: some processes" "${pids[@]}"
    audit_status=0
    "$bin/experience-audit" --config "$config" --snapshot "$dir/replay.snap" --spool "$dir/spool" \
        --executors "$n" >"$dir/audit.txt" 2>&1 || audit_status=$?
    python3 "$summary" partition "$dir" "$cut_ms" "$heal_ms" "$healed" "$audit_status" | tee "$out/partition.md"
fi
