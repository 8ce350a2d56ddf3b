#!/usr/bin/env bash
# The dissertation's Table 5.4 rows on one task, at one budget of learner updates, evaluated and
# tabulated beside the paper's figures.
#
#   deploy/experiments/table.sh [rllab|v5]          (default rllab, the paper's Ant)
#
# Rows, in order: sac-lsp (`sac-lsp train`, uniform replay), prioritized (`sac-lsp train`,
# prioritized replay), distributed (`deploy/local.sh 8`), 2l-distributed (`deploy/local.sh 8` training
# a second level on top of the distributed row's policy, frozen). Not run unless ROWS names them,
# the dissertation's other extensions on the distributed row: categorical (soft C51),
# categorical-dissertation (its own formulation), her-<goal>-<reward> (every run file
# deploy/experiments/<task>-her-*.toml; `docs/sac-lsp.md` §13-§14). Equal learner updates, as the
# dissertation's text splits them: the 1-level rows get UPDATES; the 2-level row's low level is the
# distributed row's checkpoint at 60% of UPDATES and its high level gets the other 40% (its 6,000 +
# 4,000 epochs against 10,000).
#
# Environment: UPDATES (default 150000), TABLE_ID (default table-<task>-<updates>; runs go to
# runs/<table id>-<row>/, and a row whose evaluation is there already is not run again, so a table
# can be built over several sittings), ROWS (default all four), EPISODES (evaluation episodes per row,
# default 200, the paper's), EXECUTORS (default 8), MAX_MINUTES (a wall-clock cap per row, default
# none), BUILD=0 (skip `cargo build`). Writes docs/results/<table id>.md.
#
# A row whose training fails stops the table (exit 1, naming its log): nothing older is evaluated in
# its place. A row stopped by MAX_MINUTES before its budget is evaluated at the updates it reached,
# and the table marks it with them (table.py reads each evaluation's learner_step). A table whose
# records were committed under docs/results/<table id>/ is rewritten, without training, by
# `python3 deploy/experiments/table.py <ant-rllab|ant-v5> <table id> <updates> --records docs/results/<table id>`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."

task=${1:-rllab}
case $task in
    rllab) task_name=ant-rllab ;;
    v5) task_name=ant-v5 ;;
    *) echo "table.sh: task must be rllab or v5, got '$task'" >&2; exit 2 ;;
esac
updates=${UPDATES:-150000}
[[ $updates =~ ^[0-9]+$ && $updates -ge 5000 && $((updates % 5000)) == 0 ]] ||
    { echo "table.sh: UPDATES must be a multiple of 5000, got '$updates'" >&2; exit 2; }
table_id=${TABLE_ID:-table-$task-$updates}
rows=${ROWS:-sac-lsp prioritized distributed 2l-distributed}
episodes=${EPISODES:-200}
executors=${EXECUTORS:-8}
bin=target/release
./deploy/setup.sh
if [[ ${BUILD:-1} != 0 ]]; then
    cargo build --release -p replay-server -p param-server -p learner -p executor -p sac-lsp-cli
fi

# Prints run file $1 with the lines $3 added to its table [$2] (the table appended if missing).
with_keys() {
    awk -v table="[$2]" -v lines="$3" '
        { print }
        $0 == table { print lines; done = 1 }
        END { if (!done) { print ""; print table; print lines } }' "$1"
}

# Says why row $1 failed (its log is $2) and stops the table.
row_failed() {
    echo "table.sh: $1: $3; see $2 (the table stops here)" >&2
    tail -n 5 "$2" >&2 || true
    exit 1
}

# Sets `checkpoint` to the newest file matching glob $2 (row $1's log $3), or stops the table.
newest_checkpoint() {
    checkpoint=$(ls $2 2>/dev/null | tail -n 1) || true
    [[ -n $checkpoint ]] || row_failed "$1" "$3" "no checkpoint $2 after training"
}

# Runs one row into runs/<table id>-<row>/ and sets `checkpoint` to its final checkpoint's path.
# Called as a plain command, never in $(...): bash runs a command substitution without `set -e`, and
# there a failed row went on to print (and the table to evaluate) an older checkpoint.
run_row() {
    local row=$1 dir=runs/$table_id-$1 file=deploy/experiments/$task-$1.toml status=0
    mkdir -p "$dir"
    case $row in
        sac-lsp | prioritized)
            cp "$file" "$dir/run.toml"
            # `sac-lsp train` starts afresh: an earlier sitting's checkpoints must not stand in for this
            # one's (a shorter run would leave the earlier, longer one newest).
            rm -f "$dir"/checkpoints/epoch-*.safetensors
            "$bin/sac-lsp" train --config "$dir/run.toml" --epochs $((updates / 1000 + 1)) \
                ${MAX_MINUTES:+--minutes "$MAX_MINUTES"} --out "$dir" >"$dir/train.log" 2>&1 || status=$?
            [[ $status == 0 ]] || row_failed "$row" "$dir/train.log" "sac-lsp train exited with status $status"
            newest_checkpoint "$row" "$dir/checkpoints/epoch-*.safetensors" "$dir/train.log"
            ;;
        distributed | categorical* | her-*)
            # Checkpoints every fifth of the budget: the newest three (60%, 80%, 100%) stay, and
            # the 2-level row starts from the 60% one.
            with_keys "$file" learner "max_updates = $updates
checkpoint_every_epochs = $((updates / 5000))" >"$dir/run.toml"
            RUN_ID=$table_id-$row BUILD=0 MINUTES=${MAX_MINUTES:-} ./deploy/local.sh "$executors" "$dir/run.toml" \
                >"$dir/local.log" 2>&1 || status=$?
            [[ $status == 0 ]] || row_failed "$row" "$dir/local.log" "local.sh exited with status $status"
            # A resumed row (same RUN_ID) continues its own checkpoints, so the newest is this run's.
            newest_checkpoint "$row" "$dir/checkpoints/learner-*.safetensors" "$dir/local.log"
            ;;
        2l-distributed)
            local low
            low=runs/$table_id-distributed/checkpoints/learner-$(printf %012d $((updates * 3 / 5))).safetensors
            [[ -f $low ]] || { echo "table.sh: the 2-level row needs $low (run the distributed row first)" >&2; exit 1; }
            with_keys "$file" learner "max_updates = $((updates * 2 / 5))
checkpoint_every_epochs = $((updates / 5000))" | with_keys /dev/stdin hierarchy "levels = [\"$low\"]" \
                >"$dir/run.toml"
            RUN_ID=$table_id-$row BUILD=0 MINUTES=${MAX_MINUTES:-} ./deploy/local.sh "$executors" "$dir/run.toml" \
                >"$dir/local.log" 2>&1 || status=$?
            [[ $status == 0 ]] || row_failed "$row" "$dir/local.log" "local.sh exited with status $status"
            newest_checkpoint "$row" "$dir/checkpoints/learner-*.safetensors" "$dir/local.log"
            ;;
        *) echo "table.sh: unknown row '$row'" >&2; exit 1 ;;
    esac
}

# Evaluates checkpoint $1 (run file $2) with latent $3 into $dir/$4.json and $dir/$4.csv.
evaluate() {
    "$bin/sac-lsp" eval --checkpoint "$1" --config "$2" --episodes "$episodes" --latent "$3" --seed 0 \
        --threads "$(nproc)" --csv "$dir/$4.csv" >"$dir/$4.json.tmp"
    mv "$dir/$4.json.tmp" "$dir/$4.json"
}

started=$(date +%s)
for row in $rows; do
    dir=runs/$table_id-$row
    [[ -f $dir/eval.json ]] && { echo "table.sh: $row already evaluated ($dir/eval.json)" >&2; continue; }
    echo "table.sh: $row: training ($(date +%H:%M))" >&2
    t0=$(date +%s)
    run_row "$row"
    echo $(($(date +%s) - t0)) >"$dir/train_seconds"
    [[ -f $dir/monitor.jsonl ]] && { "$bin/sac-lsp" plot --input "$dir/monitor.jsonl" --out-dir "$dir" >/dev/null || true; }
    echo "table.sh: $row: evaluating $checkpoint on $episodes episodes ($(date +%H:%M))" >&2
    if [[ $row == 2l-distributed ]]; then
        # Its frozen low level alone, evaluated the same way: what the high level has to beat.
        low=$(sed -n 's/^levels = \["\(.*\)"\]$/\1/p' "$dir/run.toml")
        evaluate "$low" "runs/$table_id-distributed/run.toml" fixed eval-low
        evaluate "$low" "runs/$table_id-distributed/run.toml" zero eval-low-zero
    fi
    # The paper's one fixed h ~ N(0, I) for all episodes hangs on one draw; h = 0 beside it.
    evaluate "$checkpoint" "$dir/run.toml" zero eval-zero
    evaluate "$checkpoint" "$dir/run.toml" fixed eval
done
python3 deploy/experiments/table.py "$task_name" "$table_id" "$updates" >"docs/results/$table_id.md"
echo "table.sh: docs/results/$table_id.md written ($(($(date +%s) - started)) s)" >&2
