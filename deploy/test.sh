#!/usr/bin/env bash
# The test command: installs what the tests need (MuJoCo 3.17's library, and ffmpeg as root; once),
# then runs every test of the workspace on the real simulator. Extra arguments go to `cargo test` (e.g. `-p sim`).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
./deploy/setup.sh --tests
# The scripts' own tests (table.sh and table.py on made-up records, about a second), then the
# workspace's. --no-fail-fast, and the scripts' failure reported at the end: one failing test must not
# hide how the others fare.
status=0
python3 deploy/experiments/test_table.py || { echo "test.sh: deploy/experiments/test_table.py failed" >&2; status=1; }
cargo test --workspace --no-fail-fast "$@" || status=$?
exit "$status"
