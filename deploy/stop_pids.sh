# Sourced by deploy/local.sh and deploy/scale.sh.
# stop_pids WHAT PID...: sends TERM to those of the processes still alive, waits up to 30 s for them
# to stop (each writes its report on a clean stop), then kills what is left, saying "WHAT did not
# stop within 30 s; killing them" on stderr.
stop_pids() {
    local what=$1 live=() pid
    shift
    for pid in "$@"; do kill -0 "$pid" 2>/dev/null && live+=("$pid"); done
    [[ ${#live[@]} -gt 0 ]] || return 0
    kill -TERM "${live[@]}" 2>/dev/null || true
    for _ in $(seq 300); do
        local any=0
        for pid in "${live[@]}"; do kill -0 "$pid" 2>/dev/null && any=1; done
        [[ $any == 0 ]] && return 0
        sleep 0.1
    done
    echo "$what did not stop within 30 s; killing them" >&2
    kill -KILL "${live[@]}" 2>/dev/null || true
}
