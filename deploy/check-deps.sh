#!/usr/bin/env bash
# The architecture's dependency rules, checked on the real dependency graph: proto and run are leaves,
# the sans-IO cores stay off the bus, the roles never depend on each other (they talk through proto),
# and the replay and param servers, which never simulate, do not link MuJoCo (run gives them the widths).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

fail=0
deps() { cargo tree -p "$1" -e normal --prefix none --format '{p}' 2>/dev/null | awk '{print $1}' | sort -u; }
forbid() { # crate, forbidden dependency...
    local crate=$1; shift
    local have; have=$(deps "$crate")
    for bad in "$@"; do
        if grep -qx "$bad" <<<"$have"; then
            echo "dependency rule broken: $crate depends on $bad" >&2
            fail=1
        fi
    done
}
roles=(replay-server param-server learner executor)
forbid proto zenoh tokio candle-core mujoco-rs sim agent node replay run "${roles[@]}"
forbid run zenoh tokio candle-core mujoco-rs proto sim agent node replay "${roles[@]}"
forbid replay-server sim mujoco-rs
forbid param-server sim mujoco-rs
forbid sim zenoh tokio candle-core proto agent node replay "${roles[@]}"
forbid agent zenoh tokio mujoco-rs proto sim node replay "${roles[@]}"
forbid replay zenoh tokio candle-core mujoco-rs sim agent node "${roles[@]}"
forbid node sim agent replay candle-core mujoco-rs "${roles[@]}"
for role in "${roles[@]}"; do
    others=()
    for r in "${roles[@]}"; do [[ $r == "$role" ]] || others+=("$r"); done
    forbid "$role" "${others[@]}"
done
[[ $fail == 0 ]] && echo "dependency rules hold"
exit $fail
